//! What validation reports: the repairs made and the facts of the result, per kind of shape.

use crate::geometry::topology::{BoundingBox, SurfaceFacts};
use crate::geometry::ShapeKind;
use serde::Serialize;

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
