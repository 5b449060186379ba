//! Triangle meshes: welded, polygons triangulated, degenerate and duplicate faces dropped, and the facts of the
//! surface.

use super::report::{Facts, MAX_EXAMPLES};
use super::weld::{compose, drop_unreferenced, weld_recorded};
use super::{Outcome, Repairs, ValidateOptions};
use crate::error::{Result, ShapeError};
use crate::geometry::topology::{self, EdgeTopology, SurfaceFacts};
use crate::geometry::triangulate::triangulate;
use crate::geometry::{vec3, Point, RawShape, Shape, TriangleMesh};
use rustc_hash::FxHashMap as HashMap;

pub(super) fn surface(
    raw: &RawShape,
    o: &ValidateOptions,
    r: &mut Repairs,
    warnings: &mut Vec<String>,
    polygons: &mut Option<crate::geometry::Polygons>,
) -> Result<Outcome> {
    let (verts, weld_map) = weld_recorded(raw, o, r);
    // Triangulate (after welding, so polygons see their true corners), remembering each triangle's polygon.
    let mut tris: Vec<[u32; 3]> = Vec::with_capacity(raw.polygons.len());
    let mut origin: Vec<u32> = Vec::with_capacity(raw.polygons.len());
    let mut repeated = Vec::new();
    let mut polygon_examples = Vec::new();
    let mut polys_split = 0usize;
    let mut corners: Vec<u32> = Vec::new();
    // The polygons as triangulated (welded numbering), kept for the polygon operator.
    let mut loops: Vec<Vec<u32>> = Vec::new();
    for (pi, poly) in raw.polygons.iter().enumerate() {
        corners.clear();
        corners.extend(poly.iter().map(|&v| weld_map[v as usize]));
        // Remove repeated consecutive corners (cyclically).
        let before = corners.len();
        corners.dedup();
        while corners.len() > 1 && corners.first() == corners.last() {
            corners.pop();
        }
        let mut distinct = corners.clone();
        distinct.sort_unstable();
        distinct.dedup();
        if corners.len() < 3 || distinct.len() < corners.len() {
            repeated.push(pi);
            if corners.len() < 3 || distinct.len() < 3 {
                continue;
            }
        } else if corners.len() < before {
            repeated.push(pi);
        }
        if corners.len() > 3 && distinct.len() == corners.len() {
            polys_split += 1;
            if polygon_examples.len() < MAX_EXAMPLES {
                polygon_examples.push(pi);
            }
        }
        loops.push(corners.clone());
        let start = tris.len();
        triangulate(&verts, &corners, &mut tris);
        origin.extend(std::iter::repeat_n(pi as u32, tris.len() - start));
    }
    let extra = tris.len().saturating_sub(raw.polygons.len() - repeated.len().min(raw.polygons.len()));
    r.add(
        "triangulated_polygons",
        &polygon_examples,
        polys_split,
        format!("{polys_split} polygons with more than three corners triangulated into {} extra triangles", extra),
    );
    // Triangles left with a repeated index (from self-touching polygons) are dropped too.
    let mut keep: Vec<bool> = tris.iter().map(|t| t[0] != t[1] && t[1] != t[2] && t[0] != t[2]).collect();
    for (i, k) in keep.iter().enumerate() {
        if !k && repeated.last() != Some(&(origin[i] as usize)) {
            repeated.push(origin[i] as usize);
        }
    }
    r.add("repeated_index", &repeated, repeated.len(), format!("{} face(s) with a repeated vertex index: repeated corners removed, faces left with fewer than three distinct corners dropped", repeated.len()));
    if o.drop_degenerate {
        let mut zero = Vec::new();
        for (i, t) in tris.iter().enumerate() {
            if keep[i] && is_zero_area(&verts, t) {
                keep[i] = false;
                zero.push(origin[i] as usize);
            }
        }
        r.add(
            "zero_area_faces",
            &zero,
            zero.len(),
            format!("{} zero-area (collinear) triangle(s) dropped", zero.len()),
        );
    }
    let mut seen: HashMap<[u32; 3], ()> = HashMap::with_capacity_and_hasher(tris.len(), Default::default());
    let mut dups = Vec::new();
    for (i, t) in tris.iter().enumerate() {
        if keep[i] {
            let mut k = *t;
            k.sort_unstable();
            if seen.insert(k, ()).is_some() {
                keep[i] = false;
                dups.push(origin[i] as usize);
            }
        }
    }
    r.add(
        "duplicate_faces",
        &dups,
        dups.len(),
        format!("{} face(s) repeating the vertex set of an earlier face dropped", dups.len()),
    );
    let faces: Vec<[u32; 3]> = tris.iter().zip(&keep).filter(|(_, &k)| k).map(|(t, _)| *t).collect();
    if faces.is_empty() {
        return Err(ShapeError::Empty {
            what: format!("no usable triangle is left of {} face(s)", raw.polygons.len()),
        });
    }
    let every_face_kept = faces.len() == tris.len() && repeated.is_empty() && loops.len() == raw.polygons.len();
    let (vertices, cmap, faces) = drop_unreferenced(&verts, &weld_map, &faces, "face", r);
    if polys_split > 0 && every_face_kept {
        let mut kept = crate::geometry::Polygons::with_capacity(loops.len(), loops.iter().map(Vec::len).sum());
        for l in &loops {
            kept.push(&l.iter().map(|&v| cmap[v as usize]).collect::<Vec<u32>>());
        }
        *polygons = Some(kept);
    }
    let mesh = TriangleMesh { vertices, faces };
    let topo = EdgeTopology::new(&mesh.faces);
    let facts = topology::surface_facts(&mesh, &topo);
    surface_warnings(&facts, warnings, "");
    Ok((Shape::TriangleMesh(mesh), compose(&weld_map, &cmap), Facts::Surface(facts)))
}

pub(super) fn surface_warnings(f: &SurfaceFacts, warnings: &mut Vec<String>, prefix: &str) {
    if f.non_manifold_edges > 0 || f.non_manifold_vertices > 0 {
        warnings.push(format!(
            "{prefix}non-manifold: {} edge(s) with more than two faces, {} vertex(es) whose faces are not edge-connected; the 'robust' operator is made for this",
            f.non_manifold_edges, f.non_manifold_vertices
        ));
    }
    if f.orientation == topology::Orientation::Inconsistent {
        warnings.push(format!(
            "{prefix}inconsistent orientation: {} edge(s) traversed in the same direction by both faces",
            f.misoriented_edges
        ));
    }
    if f.components > 1 {
        warnings.push(format!(
            "{prefix}{} connected components: the Neumann spectrum has that many zero eigenvalues",
            f.components
        ));
    }
}

/// Zero area relative to the triangle's size: 2A ≤ 10⁻¹⁰ · ℓ²_max (collinear up to rounding).
pub(super) fn is_zero_area(v: &[Point], t: &[u32; 3]) -> bool {
    let [a, b, c] = t.map(|i| v[i as usize]);
    let l2 = [vec3::sub(a, b), vec3::sub(b, c), vec3::sub(c, a)].iter().map(|e| vec3::dot(*e, *e)).fold(0.0, f64::max);
    vec3::norm(vec3::area2(a, b, c)) <= 1e-10 * l2
}
