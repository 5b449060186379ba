//! Validation: decides the shape kind, repairs what can be repaired (recording each repair with the input
//! elements it touched), refuses what cannot, and reports the facts of the result. Every repair keeps the map
//! from input vertices to output vertices so that per-vertex results can be returned in the input's numbering.
//!
//! Order of repairs for surfaces: weld duplicate vertices → triangulate polygons → drop faces with a repeated
//! index → drop zero-area faces → drop duplicate faces → drop unreferenced vertices. Tets, polylines, graphs and
//! point clouds follow the same pattern with their own rules.

mod cloud;
mod curve;
mod graph;
mod report;
mod solid;
mod surface;
mod weld;

pub use report::*;
pub use weld::{weld_exact, weld_tolerance};

use super::hash::ShapeId;
use super::topology::BoundingBox;
use super::{vec3, RawShape, Shape, ShapeKind};
use crate::error::{Element, Location, Result, ShapeError};
use cloud::cloud;
use curve::curve;
use graph::graph;
use serde::Serialize;
use solid::solid;
use surface::surface;

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
