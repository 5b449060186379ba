//! The robust Laplacian of Sharp & Crane, "A Laplacian for Nonmanifold Triangle Meshes" (SGP 2020), for
//! non-manifold, degenerate and point-cloud input:
//! 1. **tufted cover**: every face is taken twice (both sides); around each edge the sides are glued in the
//!    cyclic order of the faces about the edge, so every edge has exactly two sides — a closed, manifold
//!    (intrinsic) surface whatever the input's edge valences;
//! 2. **mollification**: δ = max(0, max over corners of ε − (l_ij + l_jk − l_ki)), ε = factor × mean edge length,
//!    is added to every length so every triangle is strictly valid (zero-area faces get a tiny positive area);
//! 3. **intrinsic Delaunay** flips on the cover, then the cotangent Laplacian with lumped mass, both halved
//!    (every face is on the cover twice).
//!
//! For point clouds, each point's triangles are those of its tangent-plane Delaunay neighbourhood (its Voronoi
//! neighbours among the k nearest, in angular order); their union is a non-manifold mesh in which most
//! triangles appear three times, so the result is divided by 3 more.
//! Sign and units as in [`super::cotan_laplacian`]; mass: lumped only.

use super::intrinsic_delaunay::IntrinsicTriangulation;
use super::point_cloud::{local_frames, voronoi_cell, Neighbourhoods};
use super::sparse::SparsePair;
use super::{Mass, OperatorError};
use crate::geometry::topology::EdgeTopology;
use crate::geometry::{vec3, Point};

/// The tufted cover of faces over positions: faces 0..F are the input, F..2F their reversed copies.
fn tufted_cover(v: &[Point], faces: &[[u32; 3]]) -> Result<IntrinsicTriangulation, OperatorError> {
    let nf = faces.len();
    let mut all: Vec<[u32; 3]> = faces.to_vec();
    all.extend(faces.iter().map(|f| [f[0], f[2], f[1]]));
    let mut length = vec![0.0; 6 * nf];
    for (f, t) in all.iter().enumerate() {
        for k in 0..3 {
            length[3 * f + k] = vec3::norm(vec3::sub(v[t[k] as usize], v[t[(k + 1) % 3] as usize]));
        }
    }
    let mut twin = vec![u32::MAX; 6 * nf];
    let topo = EdgeTopology::new(faces);
    for e in 0..topo.edges.len() {
        let [u, w] = topo.edges[e];
        let (pu, pw) = (v[u as usize], v[w as usize]);
        let axis = vec3::sub(pw, pu);
        let alen = vec3::norm(axis);
        // For each incident face: (angle about the edge, half-edge running u→w, half-edge running w→u).
        let mut around: Vec<(f64, u32, u32)> = Vec::new();
        let mut reference: Option<(Point, Point)> = None;
        for &h in topo.halfedges(e) {
            let (f, k) = (h as usize / 3, h as usize % 3);
            let opp = v[faces[f][(k + 2) % 3] as usize];
            // The reversed copy of f has the same edge as half-edge (index of the edge's corner pair) reversed.
            let back = (3 * (nf + f)
                + match k {
                    0 => 2,
                    1 => 1,
                    _ => 0,
                }) as u32;
            let fwd = (3 * f + k) as u32;
            let runs_uw = faces[f][k] == u;
            let (h_uw, h_wu) = if runs_uw { (fwd, back) } else { (back, fwd) };
            let r = vec3::sub(opp, pu);
            let along = if alen > 0.0 { vec3::dot(r, axis) / (alen * alen) } else { 0.0 };
            let radial = vec3::sub(r, vec3::scale(axis, along));
            let (x, y) = *reference.get_or_insert_with(|| {
                let rl = vec3::norm(radial);
                let x = if rl > 0.0 { vec3::scale(radial, 1.0 / rl) } else { [1.0, 0.0, 0.0] };
                let y = if alen > 0.0 { vec3::scale(vec3::cross(axis, x), 1.0 / alen) } else { [0.0, 1.0, 0.0] };
                (x, y)
            });
            around.push((vec3::dot(radial, y).atan2(vec3::dot(radial, x)), h_uw, h_wu));
        }
        around.sort_by(|a, b| a.0.total_cmp(&b.0));
        // The side of face i facing +θ (its u→w half-edge) is glued to the side of face i+1 facing −θ.
        for i in 0..around.len() {
            let a = around[i].1 as usize;
            let b = around[(i + 1) % around.len()].2 as usize;
            twin[a] = b as u32;
            twin[b] = a as u32;
        }
    }
    // Half-edge k of a reversed copy [a, c, b] runs a→c, which is the forward face's half-edge 2 reversed, etc.
    let mut t = IntrinsicTriangulation { faces: all, twin, length };
    if t.twin.contains(&u32::MAX) {
        return Err(OperatorError::InvalidParameter {
            name: "mesh",
            message: "internal: the tufted cover left an edge unglued".into(),
        });
    }
    t.faces.shrink_to_fit();
    Ok(t)
}

/// Adds δ to every length so every corner has triangle-inequality margin ε = factor × mean length.
fn mollify(t: &mut IntrinsicTriangulation, factor: f64) -> f64 {
    let mean = t.length.iter().sum::<f64>() / t.length.len().max(1) as f64;
    let eps = factor * mean;
    let mut delta: f64 = 0.0;
    for f in 0..t.faces.len() {
        let l = t.face_lengths(f);
        for k in 0..3 {
            delta = delta.max(eps - (l[(k + 1) % 3] + l[(k + 2) % 3] - l[k]));
        }
    }
    let delta = delta.max(0.0);
    if delta > 0.0 {
        t.length.iter_mut().for_each(|l| *l += delta);
    }
    delta
}

fn robust_from_faces(
    v: &[Point],
    faces: &[[u32; 3]],
    mollify_factor: f64,
    divide: f64,
) -> Result<(SparsePair, f64), OperatorError> {
    if !(mollify_factor >= 0.0 && mollify_factor.is_finite()) {
        return Err(OperatorError::InvalidParameter {
            name: "mollify",
            message: format!("{mollify_factor} is not a non-negative number"),
        });
    }
    let mut t = tufted_cover(v, faces)?;
    let delta = mollify(&mut t, mollify_factor);
    t.flip_to_delaunay();
    let mut pair = t.pair(v.len(), Mass::Lumped)?;
    pair.stiffness.iter_mut().for_each(|x| *x /= divide);
    pair.mass.iter_mut().for_each(|x| *x /= divide);
    // Vertices used by no face (possible for clouds) get unit-free tiny mass so M stays definite.
    let eps = pair.mass.iter().cloned().fold(0.0, f64::max) * 1e-12;
    for j in 0..pair.n() {
        let d = pair.pattern.diag_pos(j);
        if pair.mass[d] <= 0.0 {
            pair.mass[d] = eps.max(f64::MIN_POSITIVE);
        }
    }
    Ok((pair, delta))
}

/// The robust Laplacian of a (possibly non-manifold, degenerate) triangle mesh; returns the pair and δ.
pub fn robust_mesh_pair(
    m: &crate::geometry::TriangleMesh,
    mollify_factor: f64,
) -> Result<(SparsePair, f64), OperatorError> {
    robust_from_faces(&m.vertices, &m.faces, mollify_factor, 2.0)
}

/// The robust Laplacian of a point cloud from local tangent-plane Delaunay triangles of `k` neighbours.
pub fn robust_cloud_pair(points: &[Point], k: usize, mollify_factor: f64) -> Result<(SparsePair, f64), OperatorError> {
    let nb = Neighbourhoods::knn(points, k.max(4))?;
    let frames = local_frames(points, &nb);
    let mut faces = Vec::new();
    for i in 0..points.len() {
        let cell = voronoi_cell(points, &nb, &frames, i);
        let e = &cell.edges;
        for w in 0..e.len() {
            let (a, b) = (e[w], e[(w + 1) % e.len()]);
            if a != u32::MAX && b != u32::MAX && a != b {
                faces.push([i as u32, a, b]);
            }
        }
    }
    // Orient all local triangles the same way (consistent with the first point's frame is not needed: the
    // tufted cover uses both sides of every face).
    robust_from_faces(points, &faces, mollify_factor, 6.0)
}
