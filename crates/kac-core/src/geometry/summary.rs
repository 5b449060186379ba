//! A flat summary of a validated shape: the numbers most users look at first, with the full report beside them.
//! The CLI's `kac inspect` prints it and the service returns it for every stored shape.

use super::topology::{BoundingBox, Orientation};
use super::validate::{Facts, Report, Validated};
use super::ShapeKind;
use serde::Serialize;

#[cfg_attr(feature = "openapi", derive(utoipa::ToSchema), schema(as = ShapeSummary))]
#[derive(Debug, Clone, Serialize)]
pub struct Summary {
    /// Content hash of the canonical geometry (see [`super::hash`]).
    pub id: String,
    pub kind: ShapeKind,
    pub vertices: usize,
    /// Faces, tetrahedra, segments or edges (0 for point clouds).
    pub elements: usize,
    pub bbox: Option<BoundingBox>,
    /// Surface area (the boundary's area for a solid, length for a polyline).
    pub area: Option<f64>,
    /// Volume of a solid, or the volume enclosed by a closed, consistently oriented surface.
    pub volume: Option<f64>,
    pub length: Option<f64>,
    pub components: Option<usize>,
    pub boundary_loops: Option<usize>,
    pub closed: Option<bool>,
    pub manifold: Option<bool>,
    pub orientation: Option<Orientation>,
    pub euler_characteristic: Option<i64>,
    pub genus: Option<i64>,
    /// Whether the validated vertex numbering equals the input's.
    pub vertex_numbering_preserved: bool,
    pub warnings: Vec<String>,
    pub report: Report,
}

impl Validated {
    pub fn summary(&self) -> Summary {
        let r = &self.report;
        let mut s = Summary {
            id: self.id.hex(),
            kind: r.kind,
            vertices: self.shape.vertex_count(),
            elements: 0,
            bbox: r.bbox,
            area: None,
            volume: None,
            length: None,
            components: None,
            boundary_loops: None,
            closed: None,
            manifold: None,
            orientation: None,
            euler_characteristic: None,
            genus: None,
            vertex_numbering_preserved: self.map_is_identity(),
            warnings: r.warnings.clone(),
            report: r.clone(),
        };
        match &r.facts {
            Facts::Surface(f) => {
                s.elements = f.faces;
                s.area = Some(f.area);
                s.volume = f.enclosed_volume;
                s.components = Some(f.components);
                s.boundary_loops = Some(f.boundary_loops);
                s.closed = Some(f.closed);
                s.manifold = Some(f.manifold);
                s.orientation = Some(f.orientation);
                s.euler_characteristic = Some(f.euler_characteristic);
                s.genus = f.genus;
            }
            Facts::Solid(f) => {
                s.elements = f.tets;
                s.area = Some(f.boundary.area);
                s.volume = Some(f.volume);
                s.components = Some(f.components);
                s.boundary_loops = Some(f.boundary.boundary_loops);
                s.closed = Some(f.boundary.closed);
                s.manifold = Some(f.boundary.manifold && f.non_manifold_faces == 0);
                s.orientation = Some(f.boundary.orientation);
                s.euler_characteristic = Some(f.euler_characteristic);
                s.genus = f.boundary.genus;
            }
            Facts::Curve(f) => {
                s.elements = f.segments;
                s.length = Some(f.length);
                s.components = Some(f.components);
                s.closed = Some(f.closed_components == f.components);
                s.manifold = Some(f.branch_vertices == 0);
            }
            Facts::Graph(f) => {
                s.elements = f.edges;
                s.components = Some(f.components);
            }
            Facts::Cloud(_) => {}
        }
        s
    }
}
