//! Tetrahedral meshes: welded, degenerate and duplicate tetrahedra dropped, the boundary surface's facts.

use super::report::{Facts, SolidFacts};
use super::surface::surface_warnings;
use super::weld::{compact, compose, drop_unreferenced, weld_recorded};
use super::{Outcome, Repairs, ValidateOptions};
use crate::error::{Result, ShapeError};
use crate::geometry::topology::{self, EdgeTopology, UnionFind};
use crate::geometry::{vec3, RawShape, Shape, TetMesh, TriangleMesh};
use rustc_hash::FxHashMap as HashMap;

pub(super) fn solid(
    raw: &RawShape,
    o: &ValidateOptions,
    r: &mut Repairs,
    warnings: &mut Vec<String>,
) -> Result<Outcome> {
    let (verts, weld_map) = weld_recorded(raw, o, r);
    let mut tets = Vec::with_capacity(raw.tets.len());
    let (mut repeated, mut zero, mut inverted, mut dups) = (Vec::new(), Vec::new(), Vec::new(), Vec::new());
    let mut seen: HashMap<[u32; 4], ()> = HashMap::with_capacity_and_hasher(raw.tets.len(), Default::default());
    for (i, t) in raw.tets.iter().enumerate() {
        let mut t = t.map(|v| weld_map[v as usize]);
        let mut k = t;
        k.sort_unstable();
        if k[0] == k[1] || k[1] == k[2] || k[2] == k[3] {
            repeated.push(i);
            continue;
        }
        let p = t.map(|v| verts[v as usize]);
        let vol6 = vec3::volume6(p[0], p[1], p[2], p[3]);
        let l = (0..4)
            .flat_map(|a| (a + 1..4).map(move |b| (a, b)))
            .map(|(a, b)| vec3::norm(vec3::sub(p[a], p[b])))
            .fold(0.0, f64::max);
        if o.drop_degenerate && vol6.abs() <= 1e-10 * l * l * l {
            zero.push(i);
            continue;
        }
        if vol6 < 0.0 {
            t.swap(2, 3);
            inverted.push(i);
        }
        if seen.insert(k, ()).is_some() {
            dups.push(i);
            continue;
        }
        tets.push(t);
    }
    r.add(
        "repeated_index",
        &repeated,
        repeated.len(),
        format!("{} tetrahedra with a repeated vertex index dropped", repeated.len()),
    );
    r.add("zero_volume_tets", &zero, zero.len(), format!("{} zero-volume (flat) tetrahedra dropped", zero.len()));
    r.add(
        "inverted_tets",
        &inverted,
        inverted.len(),
        format!("{} negatively oriented tetrahedra reoriented (two vertices swapped)", inverted.len()),
    );
    r.add("duplicate_tets", &dups, dups.len(), format!("{} tetrahedra repeating an earlier one dropped", dups.len()));
    if tets.is_empty() {
        return Err(ShapeError::Empty { what: format!("no usable tetrahedron is left of {}", raw.tets.len()) });
    }
    let (vertices, cmap, tets) = drop_unreferenced(&verts, &weld_map, &tets, "tetrahedron", r);
    let mesh = TetMesh { vertices, tets };
    let (bfaces, nm_faces) = topology::tet_boundary(&mesh.tets);
    // The boundary surface on its own vertices, so its components and genus count only what it uses.
    let mut on_boundary = vec![false; mesh.vertices.len()];
    bfaces.iter().flatten().for_each(|&v| on_boundary[v as usize] = true);
    let (bverts, bmap, _) = compact(&mesh.vertices, &on_boundary);
    let bmesh = TriangleMesh { vertices: bverts, faces: bfaces.iter().map(|f| f.map(|v| bmap[v as usize])).collect() };
    let btopo = EdgeTopology::new(&bmesh.faces);
    let bfacts = topology::surface_facts(&bmesh, &btopo);
    surface_warnings(&bfacts, warnings, "boundary surface: ");
    let mut uf = UnionFind::new(mesh.vertices.len());
    for t in &mesh.tets {
        uf.union(t[0], t[1]);
        uf.union(t[0], t[2]);
        uf.union(t[0], t[3]);
    }
    let components = (0..mesh.vertices.len() as u32).filter(|&v| uf.find(v) == v).count();
    let volume: f64 = mesh
        .tets
        .iter()
        .map(|t| {
            vec3::volume6(
                mesh.vertices[t[0] as usize],
                mesh.vertices[t[1] as usize],
                mesh.vertices[t[2] as usize],
                mesh.vertices[t[3] as usize],
            ) / 6.0
        })
        .sum();
    let mut edges: Vec<[u32; 2]> = Vec::with_capacity(6 * mesh.tets.len());
    let mut tri: Vec<[u32; 3]> = Vec::with_capacity(4 * mesh.tets.len());
    for t in &mesh.tets {
        let mut s = *t;
        s.sort_unstable();
        for (a, b) in [(0, 1), (0, 2), (0, 3), (1, 2), (1, 3), (2, 3)] {
            edges.push([s[a], s[b]]);
        }
        for (a, b, c) in [(0, 1, 2), (0, 1, 3), (0, 2, 3), (1, 2, 3)] {
            tri.push([s[a], s[b], s[c]]);
        }
    }
    edges.sort_unstable();
    edges.dedup();
    tri.sort_unstable();
    tri.dedup();
    let chi = mesh.vertices.len() as i64 - edges.len() as i64 + tri.len() as i64 - mesh.tets.len() as i64;
    if nm_faces > 0 {
        warnings.push(format!("{nm_faces} triangle(s) shared by more than two tetrahedra"));
    }
    let facts = SolidFacts {
        vertices: mesh.vertices.len(),
        tets: mesh.tets.len(),
        components,
        volume,
        inverted_tets: inverted.len(),
        non_manifold_faces: nm_faces,
        euler_characteristic: chi,
        boundary: bfacts,
    };
    Ok((Shape::TetMesh(mesh), compose(&weld_map, &cmap), Facts::Solid(facts)))
}
