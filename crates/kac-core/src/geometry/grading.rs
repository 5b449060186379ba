//! Meshes graded toward the corners of a flat domain that limit the order. Near a boundary corner of interior
//! angle ω a Dirichlet or Neumann eigenfunction behaves like r^α sin(αθ) with α = π/ω, so on uniform meshes the
//! eigenvalue error of elements of degree p falls only like h^{2 min(p, α)}: re-entrant corners (α < 1) limit every
//! degree, corners above 90° (α < 2) limit P2. A mesh whose element size near the corner follows r^{1−1/β} with
//! β ≥ p/α restores the full order h^{2p} asymptotically (Babuška, Kellogg & Pitkäranta 1979; Apel, Sändig &
//! Whiteman 1996 for the radial grading used here); on practical meshes the observed order rises toward it.
//!
//! The grading is a map of the plane that moves vertices along rays from the corner: inside a ball of radius R
//! (smaller than the distance to any boundary edge that does not lie on the corner's two straight sides), a point
//! at distance r goes to distance R·g(r/R) with g(t) = t^β (β − (β − 1) t), which is C¹ at the ball's rim (g(1) = 1,
//! g′(1) = 1), increasing, and like β t^β near the corner. Rays through the corner stay rays, so the corner's two
//! sides stay on themselves and the domain is unchanged; applied to each of a family of uniformly refined meshes
//! it gives a family of graded meshes whose size parameter is still halved at each level, which is what
//! Richardson extrapolation needs.

use super::{topology::EdgeTopology, vec3, Point, TriangleMesh};

/// A boundary corner of a flat triangle mesh that limits the order (re-entrant, or above 90° for P2), and the
/// grading toward it.
#[derive(Debug, Clone, serde::Serialize)]
pub struct Corner {
    /// The corner's vertex (the mesh's numbering).
    pub vertex: u32,
    /// Its interior angle in degrees.
    pub angle_degrees: f64,
    /// The singular exponent α = π/ω of the eigenfunctions there.
    pub exponent: f64,
    /// The radius of the graded ball.
    pub radius: f64,
    /// The grading exponent β (element size ∝ r^{1−1/β} near the corner).
    pub beta: f64,
}

/// Above this many such corners the mesh is not graded (the distance search is corners × boundary edges,
/// and a boundary that jagged is better remeshed).
pub const MAX_CORNERS: usize = 256;

/// The boundary corners of a flat triangle mesh that limit the order of elements of degree p = `degree`: those
/// whose exponent α = π/ω is below p (interior angle ω above π/p by more than 10⁻⁶ rad: re-entrant corners for P1,
/// every corner above 90° for P2; α within 0.05 of an integer, such as a straight boundary's 1, is left alone), with
/// the grading exponent β = p/α, each corner's ball 0.9 of what its straight sides
/// and the rest of the boundary allow (and at most 0.45 of the distance to another corner, so balls are disjoint). Corners on a vertex where the boundary passes more than once are
/// skipped. `Err` names why nothing is graded (too many corners).
pub fn order_limiting_corners(m: &TriangleMesh, degree: u32) -> Result<Vec<Corner>, String> {
    let topo = EdgeTopology::new(&m.faces);
    let v = &m.vertices;
    // Boundary half-edges (a → b in their face's orientation), and each vertex's outgoing and incoming ones.
    let mut out_edge: Vec<Option<u32>> = vec![None; v.len()];
    let mut in_edge: Vec<Option<u32>> = vec![None; v.len()];
    let mut pinched = vec![false; v.len()];
    let mut boundary: Vec<[u32; 2]> = vec![];
    for e in 0..topo.edges.len() {
        if topo.valence(e) != 1 {
            continue;
        }
        let h = topo.halfedges(e)[0] as usize;
        let f = m.faces[h / 3];
        let (a, b) = (f[h % 3], f[(h % 3 + 1) % 3]);
        let id = boundary.len() as u32;
        boundary.push([a, b]);
        for (slot, x) in [(&mut out_edge, a), (&mut in_edge, b)] {
            if slot[x as usize].replace(id).is_some() {
                pinched[x as usize] = true;
            }
        }
    }
    // Interior angles at boundary vertices: the sum of the incident triangles' angles.
    let mut angle = vec![0.0f64; v.len()];
    for f in &m.faces {
        for k in 0..3 {
            let c = f[k] as usize;
            if out_edge[c].is_none() {
                continue;
            }
            let a = vec3::sub(v[f[(k + 1) % 3] as usize], v[c]);
            let b = vec3::sub(v[f[(k + 2) % 3] as usize], v[c]);
            angle[c] += vec3::norm(vec3::cross(a, b)).atan2(vec3::dot(a, b));
        }
    }
    let candidates: Vec<usize> = (0..v.len())
        .filter(|&c| !pinched[c] && out_edge[c].is_some() && in_edge[c].is_some())
        .filter(|&c| angle[c] > std::f64::consts::PI / f64::from(degree.max(1)) + 1e-6)
        // An integer exponent (ω = π/m: a straight boundary, a right angle) has no singular part, and one within
        // 0.05 of an integer a weak one (the nearly straight corners of a polygon standing for a curve: grading each
        // would crowd the mesh for little).
        .filter(|&c| {
            let alpha = std::f64::consts::PI / angle[c];
            (alpha - alpha.round()).abs() > 0.05
        })
        .collect();
    if candidates.len() > MAX_CORNERS {
        return Err(format!(
            "{} boundary corners limit the order (more than {MAX_CORNERS}): not graded",
            candidates.len()
        ));
    }
    let dir = |e: u32| {
        let [a, b] = boundary[e as usize];
        vec3::sub(v[b as usize], v[a as usize])
    };
    let collinear = |x: Point, y: Point| {
        let (nx, ny) = (vec3::norm(x), vec3::norm(y));
        vec3::dot(x, y) > 0.0 && vec3::norm(vec3::cross(x, y)) <= 1e-6 * nx * ny
    };
    let mut corners = vec![];
    for c in candidates {
        // The corner's two straight sides: boundary edges collinear with its first outgoing (incoming) edge.
        let mut on_sides = std::collections::HashSet::new();
        let mut side_lengths = [0.0f64; 2];
        for (side, start) in [out_edge[c], in_edge[c]].into_iter().enumerate() {
            let Some(first) = start else { continue };
            let d0 = dir(first);
            let mut e = first;
            loop {
                if !on_sides.insert(e) {
                    break;
                }
                side_lengths[side] += vec3::norm(dir(e));
                let [a, b] = boundary[e as usize];
                let next = if side == 0 { out_edge[b as usize] } else { in_edge[a as usize] };
                match next {
                    Some(n) if collinear(dir(n), d0) && !pinched[if side == 0 { b } else { a } as usize] => e = n,
                    _ => break,
                }
            }
        }
        let p = v[c];
        let mut reach = side_lengths[0].min(side_lengths[1]);
        for (i, &[a, b]) in boundary.iter().enumerate() {
            if !on_sides.contains(&(i as u32)) {
                reach = reach.min(segment_distance(p, v[a as usize], v[b as usize]));
            }
        }
        let exponent = std::f64::consts::PI / angle[c];
        corners.push(Corner {
            vertex: c as u32,
            angle_degrees: angle[c].to_degrees(),
            exponent,
            radius: 0.9 * reach,
            beta: f64::from(degree.max(1)) / exponent,
        });
    }
    // Disjoint balls: two corners' radii at most 0.45 of their distance.
    for i in 0..corners.len() {
        for j in 0..corners.len() {
            if i != j {
                let d = vec3::norm(vec3::sub(v[corners[i].vertex as usize], v[corners[j].vertex as usize]));
                corners[i].radius = corners[i].radius.min(0.45 * d);
            }
        }
    }
    Ok(corners)
}

fn segment_distance(p: Point, a: Point, b: Point) -> f64 {
    let ab = vec3::sub(b, a);
    let len2 = vec3::dot(ab, ab);
    let t = if len2 > 0.0 { (vec3::dot(vec3::sub(p, a), ab) / len2).clamp(0.0, 1.0) } else { 0.0 };
    vec3::norm(vec3::sub(p, vec3::add(a, vec3::scale(ab, t))))
}

/// The radial profile: distance r inside a ball of radius R goes to R·g(r/R).
fn profile(t: f64, beta: f64) -> f64 {
    t.powf(beta) * (beta - (beta - 1.0) * t)
}

/// The mesh with its vertices moved by the grading map of `corners` (their balls are disjoint by construction).
/// `None` when the map would fold or flatten a triangle (a mesh too coarse near a corner for its grading).
pub fn grade(m: &TriangleMesh, corners: &[Corner]) -> Option<TriangleMesh> {
    let mut vertices = m.vertices.clone();
    for corner in corners {
        let c = m.vertices[corner.vertex as usize];
        for (x, y) in m.vertices.iter().zip(vertices.iter_mut()) {
            let d = vec3::sub(*x, c);
            let r = vec3::norm(d);
            if r > 0.0 && r < corner.radius {
                let t = r / corner.radius;
                *y = vec3::add(c, vec3::scale(d, profile(t, corner.beta) / t));
            }
        }
    }
    // A triangle folds when the map turns it over, or flattens it against its own size (grading shrinks the
    // triangles at a corner by orders of magnitude, legitimately: their area is compared with their edges, not with
    // their area before).
    let folded = m.faces.iter().any(|f| {
        if f.iter().all(|&i| vertices[i as usize] == m.vertices[i as usize]) {
            return false;
        }
        let (before, after) = (super::topology::tri_area2(&m.vertices, f), super::topology::tri_area2(&vertices, f));
        let p = f.map(|i| vertices[i as usize]);
        let longest = (0..3).map(|k| vec3::norm(vec3::sub(p[(k + 1) % 3], p[k]))).fold(0.0, f64::max);
        vec3::dot(before, after) <= 0.0 || vec3::norm(after) <= 1e-12 * longest * longest
    });
    (!folded).then_some(TriangleMesh { vertices, faces: m.faces.clone() })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::geometry::{generate, refine};

    fn area(m: &TriangleMesh) -> f64 {
        m.faces.iter().map(|f| 0.5 * vec3::norm(super::super::topology::tri_area2(&m.vertices, f))).sum()
    }

    #[test]
    fn the_l_shapes_corner_is_found_and_graded_without_changing_the_domain() {
        // [0,2]² without [1,2]×[0,1]: one corner of 270° at (1, 1).
        let sq = generate::unit_square(4);
        let mut vertices = vec![];
        let mut faces = vec![];
        for (ox, oy) in [(0.0, 0.0), (0.0, 1.0), (1.0, 1.0)] {
            let base = vertices.len() as u32;
            vertices.extend(sq.vertices.iter().map(|p| [p[0] + ox, p[1] + oy, 0.0]));
            faces.extend(sq.faces.iter().map(|f| f.map(|i| i + base)));
        }
        // Merge the squares' shared vertices.
        let mut index = std::collections::HashMap::new();
        let mut merged = vec![];
        let remap: Vec<u32> = vertices
            .iter()
            .map(|p| {
                let key = ((p[0] * 8.0).round() as i64, (p[1] * 8.0).round() as i64);
                *index.entry(key).or_insert_with(|| {
                    merged.push(*p);
                    (merged.len() - 1) as u32
                })
            })
            .collect();
        let m = TriangleMesh { vertices: merged, faces: faces.iter().map(|f| f.map(|i| remap[i as usize])).collect() };
        let corners = order_limiting_corners(&m, 2).unwrap();
        assert_eq!(corners.len(), 1, "{corners:?}");
        let c = &corners[0];
        assert_eq!(m.vertices[c.vertex as usize], [1.0, 1.0, 0.0]);
        assert!((c.angle_degrees - 270.0).abs() < 1e-9 && (c.exponent - 2.0 / 3.0).abs() < 1e-12);
        assert!((c.beta - 3.0).abs() < 1e-12);
        // The straight sides run a unit length each way, and the nearest other boundary is a unit away: the ball
        // takes 0.9 of that.
        assert!((c.radius - 0.9).abs() < 1e-12, "{}", c.radius);
        let fine = refine::refine_triangles(&m);
        let g = grade(&fine, &corners).expect("no triangle folds");
        assert!((area(&g) - 3.0).abs() < 1e-12, "the domain is kept: {}", area(&g));
        // The vertices nearest the corner moved toward it by the profile, and those on its sides stayed on them.
        let near = |mesh: &TriangleMesh| {
            mesh.vertices
                .iter()
                .map(|p| vec3::norm(vec3::sub(*p, [1.0, 1.0, 0.0])))
                .filter(|&r| r > 0.0)
                .fold(f64::INFINITY, f64::min)
        };
        assert!((near(&fine) - 0.125).abs() < 1e-12);
        let t: f64 = 0.125 / 0.9;
        assert!((near(&g) - 0.9 * t.powi(3) * (3.0 - 2.0 * t)).abs() < 1e-12, "{}", near(&g));
        for (p, q) in fine.vertices.iter().zip(&g.vertices) {
            if (p[0] - 1.0).abs() < 1e-12 && p[1] < 1.0 {
                assert!((q[0] - 1.0).abs() < 1e-12 && q[1] <= 1.0);
            }
        }
    }

    #[test]
    fn convex_domains_have_no_corners_to_grade() {
        assert!(order_limiting_corners(&generate::unit_square(6), 2).unwrap().is_empty());
        assert!(order_limiting_corners(&generate::unit_disk(8), 1).unwrap().is_empty());
        // The nearly straight corners of a polygon standing for a circle (172.5°, α = 1.04) are left alone.
        assert!(order_limiting_corners(&generate::unit_disk(8), 2).unwrap().is_empty());
    }

    #[test]
    fn the_gww_drums_have_two_corners_of_270_degrees_and_two_of_135() {
        for which in [1, 2] {
            // P1: the two re-entrant corners only (β = 1/α = 1.5).
            let corners = order_limiting_corners(&generate::gww_drum(which, 2), 1).unwrap();
            let angles: Vec<f64> = corners.iter().map(|c| c.angle_degrees).collect();
            assert_eq!(angles.len(), 2, "drum {which}: {angles:?}");
            assert!(angles.iter().all(|a| (a - 270.0).abs() < 1e-9), "{angles:?}");
            assert!(corners.iter().all(|c| c.radius > 0.3 && (c.beta - 1.5).abs() < 1e-12), "{corners:?}");
            // P2: the 135° corners too (α = 4/3 < 2, β = 1.5); the 90° and 45° ones do not limit it.
            let corners = order_limiting_corners(&generate::gww_drum(which, 2), 2).unwrap();
            let mut angles: Vec<f64> = corners.iter().map(|c| c.angle_degrees.round()).collect();
            angles.sort_by(f64::total_cmp);
            assert_eq!(angles, [135.0, 135.0, 270.0, 270.0], "drum {which}");
        }
    }
}
