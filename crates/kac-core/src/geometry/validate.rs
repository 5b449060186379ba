//! Validation: decides the shape kind, repairs what can be repaired (recording each repair with the input
//! elements it touched), refuses what cannot, and reports the facts of the result. Every repair keeps the map
//! from input vertices to output vertices so that per-vertex results can be returned in the input's numbering.
//!
//! Order of repairs for surfaces: weld duplicate vertices → triangulate polygons → drop faces with a repeated
//! index → drop zero-area faces → drop duplicate faces → drop unreferenced vertices. Tets, polylines, graphs and
//! point clouds follow the same pattern with their own rules.

use super::hash::ShapeId;
use super::topology::{self, BoundingBox, EdgeTopology, SurfaceFacts, UnionFind};
use super::triangulate::triangulate;
use super::{vec3, Graph, Point, PointCloud, Polyline, RawShape, Shape, ShapeKind, TetMesh, TriangleMesh};
use crate::error::{Element, Location, Result, ShapeError};
use rustc_hash::FxHashMap as HashMap;
use serde::Serialize;

/// How duplicate vertices are merged.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, serde::Deserialize)]
#[serde(rename_all = "snake_case", tag = "mode", content = "tolerance")]
pub enum Weld {
    /// Keep every vertex, even at equal positions (glTF/OBJ seams then cut the surface).
    None,
    /// Merge vertices at exactly equal positions (the default).
    Exact,
    /// Merge vertices closer than the given distance (in the input's units).
    Tolerance(f64),
}

/// Options of validation.
#[derive(Debug, Clone, PartialEq)]
pub struct ValidateOptions {
    pub weld: Weld,
    /// Drop zero-area faces and zero-volume tets (the default). The robust Laplacian can take them when kept.
    pub drop_degenerate: bool,
    /// Read the input as this kind where it can be (e.g. a mesh's vertices as a point cloud).
    pub kind: Option<ShapeKind>,
}

impl Default for ValidateOptions {
    fn default() -> Self {
        ValidateOptions { weld: Weld::Exact, drop_degenerate: true, kind: None }
    }
}

/// A repair that was made, with up to [`MAX_EXAMPLES`] input element indices it touched.
#[cfg_attr(feature = "openapi", derive(utoipa::ToSchema))]
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Repair {
    /// Stable code: `welded_vertices`, `triangulated_polygons`, `repeated_index`, `zero_area_faces`,
    /// `zero_volume_tets`, `inverted_tets`, `duplicate_faces`, `duplicate_tets`, `duplicate_segments`,
    /// `zero_length_segments`, `self_loops`, `duplicate_edges`, `zero_weight_edges`, `unreferenced_vertices`,
    /// `duplicate_points`.
    pub code: &'static str,
    pub count: usize,
    pub message: String,
    /// Input indices (faces, tets, segments or vertices, as the code says) of the first few touched elements.
    pub examples: Vec<usize>,
}

pub const MAX_EXAMPLES: usize = 10;

/// Facts of a tetrahedral mesh.
#[cfg_attr(feature = "openapi", derive(utoipa::ToSchema))]
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct SolidFacts {
    pub vertices: usize,
    pub tets: usize,
    pub components: usize,
    pub volume: f64,
    /// Tetrahedra that were negatively oriented in the input (reoriented in the validated mesh).
    pub inverted_tets: usize,
    /// Triangles shared by more than two tets.
    pub non_manifold_faces: usize,
    pub euler_characteristic: i64,
    /// Facts of the boundary surface.
    pub boundary: SurfaceFacts,
}

/// Facts of a polyline.
#[cfg_attr(feature = "openapi", derive(utoipa::ToSchema))]
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct CurveFacts {
    pub vertices: usize,
    pub segments: usize,
    pub components: usize,
    pub closed_components: usize,
    pub endpoints: usize,
    pub branch_vertices: usize,
    pub length: f64,
}

/// Facts of a graph.
#[cfg_attr(feature = "openapi", derive(utoipa::ToSchema))]
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct GraphFacts {
    pub vertices: usize,
    pub edges: usize,
    pub components: usize,
    pub isolated_vertices: usize,
    pub total_weight: f64,
    pub min_degree: usize,
    pub max_degree: usize,
}

/// Facts of a point cloud.
#[cfg_attr(feature = "openapi", derive(utoipa::ToSchema))]
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct CloudFacts {
    pub points: usize,
    pub has_normals: bool,
    /// n for points in Rⁿ (3 for clouds in space and the plane).
    pub ambient_dimension: usize,
}

/// Kind-specific facts.
#[cfg_attr(feature = "openapi", derive(utoipa::ToSchema))]
#[derive(Debug, Clone, PartialEq, Serialize)]
#[serde(untagged)]
pub enum Facts {
    Surface(SurfaceFacts),
    Solid(SolidFacts),
    Curve(CurveFacts),
    Graph(GraphFacts),
    Cloud(CloudFacts),
}

/// Counts of the input as read.
#[cfg_attr(feature = "openapi", derive(utoipa::ToSchema))]
#[derive(Debug, Clone, PartialEq, Serialize, Default)]
pub struct InputCounts {
    pub vertices: usize,
    pub polygons: usize,
    /// Polygons with more than three corners.
    pub non_triangle_polygons: usize,
    pub tets: usize,
    pub segments: usize,
    /// Corners welded by the reader itself (STL).
    pub reader_welded: usize,
    pub planar: bool,
}

/// What validation found and did.
#[cfg_attr(feature = "openapi", derive(utoipa::ToSchema), schema(as = ValidationReport))]
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Report {
    pub kind: ShapeKind,
    pub input: InputCounts,
    pub repairs: Vec<Repair>,
    /// Findings that are not errors but matter for analysis (non-manifold, inconsistent orientation, ...).
    pub warnings: Vec<String>,
    /// What the reader skipped or interpreted.
    pub notes: Vec<String>,
    pub bbox: Option<BoundingBox>,
    pub facts: Facts,
}

/// A validated shape: canonical geometry, its id, the report, and the vertex map.
#[derive(Debug, Clone)]
pub struct Validated {
    pub shape: Shape,
    pub id: ShapeId,
    pub report: Report,
    /// For each input vertex, its index in `shape`, or `u32::MAX` where it was dropped.
    pub vertex_map: Vec<u32>,
    /// A surface read from polygons with more than three corners: those polygons as given (corners in the
    /// shape's numbering), for the `polygon` operator; `None` where every face is a triangle, or where a repair
    /// dropped or split faces (then the triangles are the mesh).
    pub polygons: Option<std::sync::Arc<super::Polygons>>,
    /// The input's middle nodes of curved edges (second-order elements), in the shape's numbering, for quadratic
    /// elements; `None` where none is off its straight edge's midpoint.
    pub edge_nodes: Option<std::sync::Arc<super::EdgeNodes>>,
}

impl Validated {
    /// Whether the vertex map is the identity (no vertex was merged, dropped or moved).
    pub fn map_is_identity(&self) -> bool {
        self.vertex_map.len() == self.shape.vertex_count()
            && self.vertex_map.iter().enumerate().all(|(i, &m)| m as usize == i)
    }
    /// Spreads per-vertex values of the validated shape back to the input's numbering (`fill` where dropped).
    pub fn to_input_numbering<T: Copy>(&self, values: &[T], fill: T) -> Vec<T> {
        self.vertex_map.iter().map(|&m| if m == u32::MAX { fill } else { values[m as usize] }).collect()
    }
}

struct Repairs(Vec<Repair>);

impl Repairs {
    fn add(&mut self, code: &'static str, examples: &[usize], count: usize, message: String) {
        if count > 0 {
            self.0.push(Repair {
                code,
                count,
                message,
                examples: examples.iter().take(MAX_EXAMPLES).copied().collect(),
            });
        }
    }
}

/// Welds exactly equal positions (−0 equals +0). Returns the unique positions in order of first appearance,
/// the map from each input position to its unique index, and the number merged.
pub fn weld_exact(points: &[Point]) -> (Vec<Point>, Vec<u32>, usize) {
    let key = |p: &Point| p.map(|c| if c == 0.0 { 0u64 } else { c.to_bits() });
    let mut seen: HashMap<[u64; 3], u32> = HashMap::with_capacity_and_hasher(points.len() / 2, Default::default());
    let mut unique = Vec::with_capacity(points.len() / 2);
    let map = points
        .iter()
        .map(|p| {
            *seen.entry(key(p)).or_insert_with(|| {
                unique.push(*p);
                (unique.len() - 1) as u32
            })
        })
        .collect();
    let merged = points.len() - unique.len();
    (unique, map, merged)
}

/// Welds positions closer than `tol` (single linkage through a grid of cell `tol`): every cluster becomes
/// the position of its first member.
pub fn weld_tolerance(points: &[Point], tol: f64) -> (Vec<Point>, Vec<u32>, usize) {
    if !(tol > 0.0 && tol.is_finite()) {
        return weld_exact(points);
    }
    let cell = |p: &Point| p.map(|c| (c / tol).floor() as i64);
    let mut grid: HashMap<[i64; 3], Vec<u32>> = HashMap::default();
    for (i, p) in points.iter().enumerate() {
        grid.entry(cell(p)).or_default().push(i as u32);
    }
    let mut uf = UnionFind::new(points.len());
    for (i, p) in points.iter().enumerate() {
        let c = cell(p);
        for dx in -1..=1 {
            for dy in -1..=1 {
                for dz in -1..=1 {
                    if let Some(list) = grid.get(&[c[0] + dx, c[1] + dy, c[2] + dz]) {
                        for &j in list {
                            if (j as usize) < i && vec3::norm(vec3::sub(*p, points[j as usize])) <= tol {
                                uf.union(i as u32, j);
                            }
                        }
                    }
                }
            }
        }
    }
    let mut root_index: HashMap<u32, u32> = HashMap::default();
    let mut unique = Vec::new();
    let map = (0..points.len() as u32)
        .map(|i| {
            let r = uf.find(i);
            *root_index.entry(r).or_insert_with(|| {
                unique.push(points[i as usize]);
                (unique.len() - 1) as u32
            })
        })
        .collect();
    let merged = points.len() - unique.len();
    (unique, map, merged)
}

fn weld(points: &[Point], w: Weld) -> (Vec<Point>, Vec<u32>, usize) {
    match w {
        Weld::None => (points.to_vec(), (0..points.len() as u32).collect(), 0),
        Weld::Exact => weld_exact(points),
        Weld::Tolerance(t) => weld_tolerance(points, t),
    }
}

/// Drops vertices no element references; returns the compacted positions and the old→new map (u32::MAX: dropped).
fn compact(vertices: &[Point], used: &[bool]) -> (Vec<Point>, Vec<u32>, Vec<usize>) {
    let mut map = vec![u32::MAX; vertices.len()];
    let mut out = Vec::with_capacity(vertices.len());
    let mut dropped = Vec::new();
    for (i, p) in vertices.iter().enumerate() {
        if used[i] {
            map[i] = out.len() as u32;
            out.push(*p);
        } else {
            dropped.push(i);
        }
    }
    (out, map, dropped)
}

/// Welds the raw vertices as the options say and records the repair.
fn weld_recorded(raw: &RawShape, o: &ValidateOptions, r: &mut Repairs) -> (Vec<Point>, Vec<u32>) {
    let (verts, weld_map, merged) = weld(&raw.vertices, o.weld);
    r.add("welded_vertices", &[], merged, format!("{merged} vertices at equal positions merged"));
    (verts, weld_map)
}

/// Drops vertices no element uses, renumbers the elements, records the repair (with input indices through
/// `weld_map`), and returns the kept positions, the welded→kept map and the renumbered elements.
fn drop_unreferenced<const A: usize>(
    verts: &[Point],
    weld_map: &[u32],
    elems: &[[u32; A]],
    element_name: &str,
    r: &mut Repairs,
) -> (Vec<Point>, Vec<u32>, Vec<[u32; A]>) {
    let mut used = vec![false; verts.len()];
    elems.iter().flatten().for_each(|&v| used[v as usize] = true);
    let (vertices, cmap, dropped) = compact(verts, &used);
    let dropped_input: Vec<usize> =
        weld_map.iter().enumerate().filter(|(_, &w)| cmap[w as usize] == u32::MAX).map(|(i, _)| i).collect();
    r.add(
        "unreferenced_vertices",
        &dropped_input,
        dropped.len(),
        format!("{} vertex(es) used by no {element_name} dropped", dropped.len()),
    );
    let renumbered = elems.iter().map(|e| e.map(|v| cmap[v as usize])).collect();
    (vertices, cmap, renumbered)
}

fn compose(first: &[u32], second: &[u32]) -> Vec<u32> {
    first.iter().map(|&m| if m == u32::MAX { u32::MAX } else { second[m as usize] }).collect()
}

/// Validates a raw shape.
pub fn validate(raw: RawShape, options: &ValidateOptions) -> Result<Validated> {
    let input = InputCounts {
        vertices: raw.graph_vertex_count.unwrap_or(raw.vertices.len()),
        polygons: raw.polygons.len(),
        non_triangle_polygons: raw.polygons.iter().filter(|p| p.len() > 3).count(),
        tets: raw.tets.len(),
        segments: raw.segments.len(),
        reader_welded: raw.reader_welded,
        planar: raw.planar_input,
    };
    // Defensive: readers check ranges, but a RawShape may be built by hand.
    let nv = input.vertices;
    let check = |idx: &mut dyn Iterator<Item = (usize, u32)>, element: Element| -> Result<()> {
        for (e, v) in idx {
            if v as usize >= nv {
                return Err(ShapeError::IndexOutOfRange {
                    element,
                    index: e,
                    value: v as i64,
                    vertex_count: nv,
                    location: Location::Unknown,
                });
            }
        }
        Ok(())
    };
    check(&mut raw.polygons.iter().enumerate().flat_map(|(e, p)| p.iter().map(move |&v| (e, v))), Element::Face)?;
    check(&mut raw.tets.iter().enumerate().flat_map(|(e, t)| t.iter().map(move |&v| (e, v))), Element::Tetrahedron)?;
    check(&mut raw.segments.iter().enumerate().flat_map(|(e, s)| s.iter().map(move |&v| (e, v))), Element::Segment)?;
    if let Some((i, p)) = raw.vertices.iter().enumerate().find(|(_, p)| !p.iter().all(|c| c.is_finite())) {
        let bad = p.iter().copied().find(|c| !c.is_finite()).unwrap_or(f64::NAN);
        return Err(ShapeError::NonFinite {
            element: Element::Vertex,
            index: i,
            value: bad.to_string(),
            location: Location::Unknown,
        });
    }

    let kind = match options.kind {
        Some(k) => k,
        None if !raw.tets.is_empty() => ShapeKind::TetMesh,
        None if !raw.polygons.is_empty() => ShapeKind::TriangleMesh,
        None if raw.is_graph => ShapeKind::Graph,
        None if !raw.segments.is_empty() => ShapeKind::Polyline,
        None => ShapeKind::PointCloud,
    };
    let mut notes = raw.notes.clone();
    let ignored = |what: &str, n: usize, notes: &mut Vec<String>| {
        if n > 0 {
            notes.push(format!("{n} {what} ignored: the shape is read as a {}", kind.as_str()));
        }
    };
    match kind {
        ShapeKind::TetMesh => {
            ignored("polygon(s)", raw.polygons.len(), &mut notes);
            ignored("segment(s)", raw.segments.len(), &mut notes);
        }
        ShapeKind::TriangleMesh => {
            ignored("tetrahedra", raw.tets.len(), &mut notes);
            ignored("segment(s)", raw.segments.len(), &mut notes);
        }
        ShapeKind::Polyline | ShapeKind::Graph => {
            ignored("polygon(s)", raw.polygons.len(), &mut notes);
            ignored("tetrahedra", raw.tets.len(), &mut notes);
        }
        ShapeKind::PointCloud => {
            ignored("element(s)", raw.polygons.len() + raw.tets.len() + raw.segments.len(), &mut notes);
        }
    }
    let mut repairs = Repairs(Vec::new());
    let mut warnings = raw.warnings.clone();
    let mut polygons = None;
    let (shape, vertex_map, facts) = match kind {
        ShapeKind::TriangleMesh => surface(&raw, options, &mut repairs, &mut warnings, &mut polygons)?,
        ShapeKind::TetMesh => solid(&raw, options, &mut repairs, &mut warnings)?,
        ShapeKind::Polyline => curve(&raw, options, &mut repairs)?,
        ShapeKind::Graph => graph(&raw, &mut repairs)?,
        ShapeKind::PointCloud => cloud(&raw, options, &mut repairs)?,
    };
    let bbox = shape.positions().and_then(BoundingBox::of);
    let edge_nodes = edge_nodes(&raw, &shape, &vertex_map, &mut notes, &mut warnings);
    let id = super::hash::shape_id_with(&shape, polygons.as_ref(), edge_nodes.as_ref());
    Ok(Validated {
        shape,
        id,
        report: Report { kind, input, repairs: repairs.0, warnings, notes, bbox, facts },
        vertex_map,
        polygons: polygons.map(std::sync::Arc::new),
        edge_nodes: edge_nodes.map(std::sync::Arc::new),
    })
}

/// The input's edge middle nodes carried to the shape's numbering, for the mesh's edges only; `None` where there
/// are none, where every one lies on its straight edge's midpoint (they change nothing), or where one lies more
/// than a quarter of its edge's length from that midpoint (a map that far from affine may fold: then all are
/// ignored, with a warning).
fn edge_nodes(
    raw: &RawShape,
    shape: &Shape,
    vertex_map: &[u32],
    notes: &mut Vec<String>,
    warnings: &mut Vec<String>,
) -> Option<super::EdgeNodes> {
    if raw.edge_nodes.is_empty() {
        return None;
    }
    let (vertices, edges) = match shape {
        Shape::TriangleMesh(m) => (&m.vertices, super::topology::triangle_edges(&m.faces)),
        Shape::TetMesh(m) => (&m.vertices, super::topology::tet_edges(&m.tets)),
        _ => return None,
    };
    let mapped = raw.edge_nodes.iter().filter_map(|&([a, b], p)| {
        let (x, y) = (*vertex_map.get(a as usize)?, *vertex_map.get(b as usize)?);
        let e = [x.min(y), x.max(y)];
        (x != u32::MAX && y != u32::MAX && x != y && edges.binary_search(&e).is_ok()).then_some((e, p))
    });
    let nodes = super::EdgeNodes::new(mapped.collect());
    let (mut curved, mut far) = (0usize, 0usize);
    for &([a, b], p) in nodes.iter() {
        let (pa, pb) = (vertices[a as usize], vertices[b as usize]);
        let length = vec3::norm(vec3::sub(pb, pa));
        let off = vec3::norm(vec3::sub(p, vec3::scale(vec3::add(pa, pb), 0.5)));
        curved += usize::from(off > 1e-9 * length);
        far += usize::from(off > 0.25 * length);
    }
    if far > 0 {
        warnings.push(format!(
            "{far} edge middle node(s) lie more than a quarter of their edge's length from its midpoint: every \
             edge node is ignored (quadratic elements use straight edges)"
        ));
        return None;
    }
    if curved == 0 {
        return None;
    }
    notes.push(format!(
        "{curved} of {} edges curved by the input's middle nodes (used by quadratic elements, order 2)",
        edges.len()
    ));
    Some(nodes)
}

type Outcome = (Shape, Vec<u32>, Facts);

fn surface(
    raw: &RawShape,
    o: &ValidateOptions,
    r: &mut Repairs,
    warnings: &mut Vec<String>,
    polygons: &mut Option<super::Polygons>,
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
        let mut kept = super::Polygons::with_capacity(loops.len(), loops.iter().map(Vec::len).sum());
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

fn surface_warnings(f: &SurfaceFacts, warnings: &mut Vec<String>, prefix: &str) {
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
fn is_zero_area(v: &[Point], t: &[u32; 3]) -> bool {
    let [a, b, c] = t.map(|i| v[i as usize]);
    let l2 = [vec3::sub(a, b), vec3::sub(b, c), vec3::sub(c, a)].iter().map(|e| vec3::dot(*e, *e)).fold(0.0, f64::max);
    vec3::norm(vec3::area2(a, b, c)) <= 1e-10 * l2
}

fn solid(raw: &RawShape, o: &ValidateOptions, r: &mut Repairs, warnings: &mut Vec<String>) -> Result<Outcome> {
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

fn curve(raw: &RawShape, o: &ValidateOptions, r: &mut Repairs) -> Result<Outcome> {
    let (verts, weld_map) = weld_recorded(raw, o, r);
    let mut segs = Vec::with_capacity(raw.segments.len());
    let (mut zero, mut dups) = (Vec::new(), Vec::new());
    let mut seen: HashMap<[u32; 2], ()> = HashMap::default();
    for (i, s) in raw.segments.iter().enumerate() {
        let s = s.map(|v| weld_map[v as usize]);
        if s[0] == s[1] {
            zero.push(i);
            continue;
        }
        let k = if s[0] < s[1] { s } else { [s[1], s[0]] };
        if seen.insert(k, ()).is_some() {
            dups.push(i);
            continue;
        }
        segs.push(s);
    }
    r.add(
        "zero_length_segments",
        &zero,
        zero.len(),
        format!("{} segment(s) joining a vertex to itself dropped", zero.len()),
    );
    r.add(
        "duplicate_segments",
        &dups,
        dups.len(),
        format!("{} segment(s) repeating an earlier one dropped", dups.len()),
    );
    if segs.is_empty() {
        return Err(ShapeError::Empty { what: format!("no usable segment is left of {}", raw.segments.len()) });
    }
    let (vertices, cmap, segments) = drop_unreferenced(&verts, &weld_map, &segs, "segment", r);
    let n = vertices.len();
    let mut degree = vec![0usize; n];
    let mut uf = UnionFind::new(n);
    for s in &segments {
        degree[s[0] as usize] += 1;
        degree[s[1] as usize] += 1;
        uf.union(s[0], s[1]);
    }
    let (labels, components) = uf.labels();
    let mut all_two = vec![true; components];
    for v in 0..n {
        if degree[v] != 2 {
            all_two[labels[v] as usize] = false;
        }
    }
    let length = segments.iter().map(|s| vec3::norm(vec3::sub(vertices[s[0] as usize], vertices[s[1] as usize]))).sum();
    let facts = CurveFacts {
        vertices: n,
        segments: segments.len(),
        components,
        closed_components: all_two.iter().filter(|&&x| x).count(),
        endpoints: degree.iter().filter(|&&d| d == 1).count(),
        branch_vertices: degree.iter().filter(|&&d| d > 2).count(),
        length,
    };
    Ok((Shape::Polyline(Polyline { vertices, segments }), compose(&weld_map, &cmap), Facts::Curve(facts)))
}

fn graph(raw: &RawShape, r: &mut Repairs) -> Result<Outcome> {
    let n = raw.graph_vertex_count.unwrap_or(raw.vertices.len());
    if n == 0 {
        return Err(ShapeError::Empty { what: "the graph has no vertices".into() });
    }
    let weights = raw.weights.clone().unwrap_or_else(|| vec![1.0; raw.segments.len()]);
    let mut merged: HashMap<[u32; 2], usize> = HashMap::default();
    let mut edges: Vec<[u32; 2]> = Vec::new();
    let mut w: Vec<f64> = Vec::new();
    let (mut loops, mut dups, mut zero) = (Vec::new(), Vec::new(), Vec::new());
    for (i, (s, &wi)) in raw.segments.iter().zip(&weights).enumerate() {
        if !wi.is_finite() || wi < 0.0 {
            return Err(ShapeError::InvalidElement {
                element: Element::Edge,
                index: i,
                rule: format!("edge weights must be finite and non-negative, this one is {wi}"),
                location: Location::pointer(format!("/weights/{i}")),
            });
        }
        if s[0] == s[1] {
            loops.push(i);
            continue;
        }
        if wi == 0.0 {
            zero.push(i);
            continue;
        }
        let k = if s[0] < s[1] { *s } else { [s[1], s[0]] };
        match merged.get(&k) {
            Some(&j) => {
                w[j] += wi;
                dups.push(i);
            }
            None => {
                merged.insert(k, edges.len());
                edges.push(k);
                w.push(wi);
            }
        }
    }
    r.add(
        "self_loops",
        &loops,
        loops.len(),
        format!("{} self-loop(s) dropped (they do not change a Laplacian)", loops.len()),
    );
    r.add("zero_weight_edges", &zero, zero.len(), format!("{} edge(s) of weight 0 dropped", zero.len()));
    r.add(
        "duplicate_edges",
        &dups,
        dups.len(),
        format!("{} repeated edge(s) merged into one, weights summed", dups.len()),
    );
    let mut degree = vec![0usize; n];
    let mut uf = UnionFind::new(n);
    for e in &edges {
        degree[e[0] as usize] += 1;
        degree[e[1] as usize] += 1;
        uf.union(e[0], e[1]);
    }
    let (_, components) = uf.labels();
    let facts = GraphFacts {
        vertices: n,
        edges: edges.len(),
        components,
        isolated_vertices: degree.iter().filter(|&&d| d == 0).count(),
        total_weight: w.iter().sum(),
        min_degree: degree.iter().copied().min().unwrap_or(0),
        max_degree: degree.iter().copied().max().unwrap_or(0),
    };
    let positions = (!raw.vertices.is_empty()).then(|| raw.vertices.clone());
    let g = Graph { vertex_count: n, positions, edges, weights: w };
    Ok((Shape::Graph(g), (0..n as u32).collect(), Facts::Graph(facts)))
}

fn cloud(raw: &RawShape, o: &ValidateOptions, r: &mut Repairs) -> Result<Outcome> {
    if raw.vertices.is_empty() {
        return Err(ShapeError::Empty { what: "no vertices or points".into() });
    }
    // Points in Rⁿ merge only where every coordinate agrees (the first three may coincide for distinct points).
    let (points, map, merged, ambient) = match &raw.ambient {
        Some(a) => weld_rows(a, &raw.vertices),
        None => {
            let (points, map, merged) = weld(&raw.vertices, o.weld);
            (points, map, merged, None)
        }
    };
    let mut first = vec![usize::MAX; points.len()];
    let mut dup_examples = Vec::new();
    for (i, &m) in map.iter().enumerate() {
        if first[m as usize] == usize::MAX {
            first[m as usize] = i;
        } else if dup_examples.len() < MAX_EXAMPLES {
            dup_examples.push(i);
        }
    }
    r.add("duplicate_points", &dup_examples, merged, format!("{merged} point(s) at the position of an earlier point merged (k-nearest-neighbour weights need distinct points)"));
    let normals = raw.normals.as_ref().map(|ns| {
        let mut out = vec![[0.0; 3]; points.len()];
        let mut set = vec![false; points.len()];
        for (i, &m) in map.iter().enumerate() {
            if !set[m as usize] {
                out[m as usize] = ns[i];
                set[m as usize] = true;
            }
        }
        out
    });
    let ambient_dimension = ambient.as_ref().map_or(3, |a: &super::Ambient| a.dim);
    let facts = CloudFacts { points: points.len(), has_normals: normals.is_some(), ambient_dimension };
    Ok((Shape::PointCloud(PointCloud { points, normals, ambient }), map, Facts::Cloud(facts)))
}

/// Exact duplicates among points in Rⁿ merged (all coordinates equal; ±0 alike): the unique points' first three
/// coordinates, the input → unique map, the merged count, and the unique rows.
fn weld_rows(a: &super::Ambient, first3: &[Point]) -> (Vec<Point>, Vec<u32>, usize, Option<super::Ambient>) {
    let mut seen: HashMap<Vec<u64>, u32> = HashMap::with_capacity_and_hasher(a.len(), Default::default());
    let (mut points, mut coords) = (Vec::with_capacity(a.len()), Vec::with_capacity(a.coords.len()));
    let map: Vec<u32> = (0..a.len())
        .map(|i| {
            let row = a.row(i);
            let key: Vec<u64> = row.iter().map(|&c| if c == 0.0 { 0 } else { c.to_bits() }).collect();
            *seen.entry(key).or_insert_with(|| {
                points.push(first3[i]);
                coords.extend_from_slice(row);
                (points.len() - 1) as u32
            })
        })
        .collect();
    let merged = a.len() - points.len();
    (points, map, merged, Some(super::Ambient { dim: a.dim, coords }))
}
