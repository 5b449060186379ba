//! Shape kinds kac analyses, in their canonical (validated) form, and the raw form readers produce.
//!
//! Coordinates are `f64`; 2-D input is embedded at z = 0. Indices are `u32` (a shape has fewer than 2³² vertices).
//! This module has no I/O and no HTTP; readers live in [`crate::io`].

pub mod generate;
pub mod grading;
pub mod hash;
pub mod numbering;
pub mod refine;
pub mod summary;
pub mod topology;
pub mod triangulate;
pub mod validate;

use serde::Serialize;

/// A point of R³.
pub type Point = [f64; 3];

/// A triangle mesh (a surface); faces are counter-clockwise seen from outside where the input says so.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct TriangleMesh {
    pub vertices: Vec<Point>,
    pub faces: Vec<[u32; 3]>,
}

/// A tetrahedral mesh (a solid); after validation every tetrahedron has positive signed volume.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct TetMesh {
    pub vertices: Vec<Point>,
    pub tets: Vec<[u32; 4]>,
}

/// Points sampled from a surface (or, with `ambient`, from a manifold in Rⁿ), optionally with normals.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct PointCloud {
    /// The first three coordinates of each point (all of them in R³ and the plane).
    pub points: Vec<Point>,
    pub normals: Option<Vec<Point>>,
    /// Points in Rⁿ, n ≥ 4 (manifold learning): every coordinate; `points` holds the first three, for drawing.
    pub ambient: Option<Ambient>,
}

/// Coordinates of points in Rⁿ (n ≥ 4), row-major: point i is `coords[i * dim..(i + 1) * dim]`.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct Ambient {
    pub dim: usize,
    pub coords: Vec<f64>,
}

impl Ambient {
    pub fn row(&self, i: usize) -> &[f64] {
        &self.coords[i * self.dim..(i + 1) * self.dim]
    }
    pub fn len(&self) -> usize {
        self.coords.len() / self.dim.max(1)
    }
    pub fn is_empty(&self) -> bool {
        self.coords.is_empty()
    }
}

/// A weighted undirected graph on `vertex_count` vertices; `positions` where the input gives them.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct Graph {
    pub vertex_count: usize,
    pub positions: Option<Vec<Point>>,
    pub edges: Vec<[u32; 2]>,
    /// One positive weight per edge.
    pub weights: Vec<f64>,
}

/// A 1-D shape: vertices joined by straight segments (one or several open or closed polylines).
#[derive(Debug, Clone, PartialEq, Default)]
pub struct Polyline {
    pub vertices: Vec<Point>,
    pub segments: Vec<[u32; 2]>,
}

/// Every shape kind kac takes.
#[derive(Debug, Clone, PartialEq)]
pub enum Shape {
    TriangleMesh(TriangleMesh),
    TetMesh(TetMesh),
    PointCloud(PointCloud),
    Graph(Graph),
    Polyline(Polyline),
}

/// The kind of a [`Shape`], as named in JSON.
#[cfg_attr(feature = "openapi", derive(utoipa::ToSchema))]
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize, serde::Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum ShapeKind {
    TriangleMesh,
    TetMesh,
    PointCloud,
    Graph,
    Polyline,
}

impl ShapeKind {
    pub fn as_str(self) -> &'static str {
        match self {
            ShapeKind::TriangleMesh => "triangle_mesh",
            ShapeKind::TetMesh => "tet_mesh",
            ShapeKind::PointCloud => "point_cloud",
            ShapeKind::Graph => "graph",
            ShapeKind::Polyline => "polyline",
        }
    }
}

impl Shape {
    pub fn kind(&self) -> ShapeKind {
        match self {
            Shape::TriangleMesh(_) => ShapeKind::TriangleMesh,
            Shape::TetMesh(_) => ShapeKind::TetMesh,
            Shape::PointCloud(_) => ShapeKind::PointCloud,
            Shape::Graph(_) => ShapeKind::Graph,
            Shape::Polyline(_) => ShapeKind::Polyline,
        }
    }

    /// Number of vertices (points for a cloud), i.e. the size of per-vertex arrays.
    pub fn vertex_count(&self) -> usize {
        match self {
            Shape::TriangleMesh(m) => m.vertices.len(),
            Shape::TetMesh(m) => m.vertices.len(),
            Shape::PointCloud(c) => c.points.len(),
            Shape::Graph(g) => g.vertex_count,
            Shape::Polyline(p) => p.vertices.len(),
        }
    }

    /// Vertex positions, where the shape has them.
    pub fn positions(&self) -> Option<&[Point]> {
        match self {
            Shape::TriangleMesh(m) => Some(&m.vertices),
            Shape::TetMesh(m) => Some(&m.vertices),
            Shape::PointCloud(c) => Some(&c.points),
            Shape::Graph(g) => g.positions.as_deref(),
            Shape::Polyline(p) => Some(&p.vertices),
        }
    }
}

/// Polygons of varying size stored flat: polygon `i` is `indices[offsets[i]..offsets[i + 1]]`.
#[derive(Debug, Clone, PartialEq)]
pub struct Polygons {
    pub indices: Vec<u32>,
    pub offsets: Vec<usize>,
}

impl Default for Polygons {
    fn default() -> Self {
        Polygons { indices: Vec::new(), offsets: vec![0] }
    }
}

impl Polygons {
    pub fn with_capacity(polygons: usize, indices: usize) -> Self {
        let mut offsets = Vec::with_capacity(polygons + 1);
        offsets.push(0);
        Polygons { indices: Vec::with_capacity(indices), offsets }
    }
    pub fn len(&self) -> usize {
        self.offsets.len() - 1
    }
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }
    pub fn get(&self, i: usize) -> &[u32] {
        &self.indices[self.offsets[i]..self.offsets[i + 1]]
    }
    pub fn push(&mut self, polygon: &[u32]) {
        self.indices.extend_from_slice(polygon);
        self.offsets.push(self.indices.len());
    }
    /// Ends the polygon whose indices were pushed with `indices.push` since the last call.
    pub fn close(&mut self) {
        self.offsets.push(self.indices.len());
    }
    pub fn iter(&self) -> impl Iterator<Item = &[u32]> + '_ {
        self.offsets.windows(2).map(move |w| &self.indices[w[0]..w[1]])
    }
    pub fn from_triangles(triangles: &[[u32; 3]]) -> Self {
        Polygons {
            indices: triangles.iter().flatten().copied().collect(),
            offsets: (0..=triangles.len()).map(|i| 3 * i).collect(),
        }
    }
}

/// What a reader produced, before validation. Readers check syntax, finiteness and index ranges (they know the
/// line or byte offset); [`validate::validate`] decides the kind, repairs and reports.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct RawShape {
    pub vertices: Vec<Point>,
    /// Surface faces (polygons; triangles are the common case).
    pub polygons: Polygons,
    pub tets: Vec<[u32; 4]>,
    /// Segments: polyline pieces or graph edges.
    pub segments: Vec<[u32; 2]>,
    /// Graph edge weights (one per segment) when the input is a weighted graph.
    pub weights: Option<Vec<f64>>,
    /// Per-vertex normals of a point cloud.
    pub normals: Option<Vec<Point>>,
    /// Point coordinates in Rⁿ, n ≥ 4 (`vertices` then holds the first three of each).
    pub ambient: Option<Ambient>,
    /// The input declares its segments to be a graph (edges), not a polyline.
    pub is_graph: bool,
    /// Vertex count of a graph given without positions (then `vertices` is empty).
    pub graph_vertex_count: Option<usize>,
    /// Whether coordinates came with only two components (embedded at z = 0).
    pub planar_input: bool,
    /// Vertices welded by the reader itself (STL stores no shared vertices), before validation.
    pub reader_welded: usize,
    /// Notes of the reader: content skipped or interpreted, for the report.
    pub notes: Vec<String>,
    /// Warnings of the reader: what it read may not be what the file meant (an OBJ with no faces, read as a
    /// point cloud, may be a mesh cut short).
    pub warnings: Vec<String>,
    /// Middle nodes of edges given by second-order elements (Gmsh 6-node triangles, 10-node tets, 8/9-node
    /// quads, 3-node lines): the edge's two corners (this numbering) and the node's position.
    pub edge_nodes: Vec<([u32; 2], Point)>,
}

/// Where the input placed the middle node of its mesh's edges (second-order elements), in the shape's numbering:
/// the geometry of curved (isoparametric) quadratic elements. Sorted by edge (smaller index first), one per edge;
/// edges without a node are straight.
#[derive(Debug, Clone, PartialEq)]
pub struct EdgeNodes(Vec<([u32; 2], Point)>);

impl EdgeNodes {
    /// From (edge, position) pairs in any order and orientation; the first node of an edge given twice wins.
    pub fn new(mut nodes: Vec<([u32; 2], Point)>) -> Self {
        for (e, _) in &mut nodes {
            e.sort_unstable();
        }
        nodes.sort_by_key(|(e, _)| *e);
        nodes.dedup_by_key(|(e, _)| *e);
        EdgeNodes(nodes)
    }
    /// The middle node of edge {a, b}, where the input gave one.
    pub fn get(&self, [a, b]: [u32; 2]) -> Option<Point> {
        let e = [a.min(b), a.max(b)];
        self.0.binary_search_by_key(&e, |(x, _)| *x).ok().map(|i| self.0[i].1)
    }
    pub fn len(&self) -> usize {
        self.0.len()
    }
    pub fn is_empty(&self) -> bool {
        self.0.is_empty()
    }
    pub fn iter(&self) -> impl Iterator<Item = &([u32; 2], Point)> + '_ {
        self.0.iter()
    }
}

/// Componentwise helpers on points.
pub(crate) mod vec3 {
    use super::Point;
    #[inline]
    pub fn sub(a: Point, b: Point) -> Point {
        [a[0] - b[0], a[1] - b[1], a[2] - b[2]]
    }
    #[inline]
    pub fn cross(a: Point, b: Point) -> Point {
        [a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]]
    }
    #[inline]
    pub fn dot(a: Point, b: Point) -> f64 {
        a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
    }
    #[inline]
    pub fn norm(a: Point) -> f64 {
        dot(a, a).sqrt()
    }
    #[inline]
    pub fn add(a: Point, b: Point) -> Point {
        [a[0] + b[0], a[1] + b[1], a[2] + b[2]]
    }
    #[inline]
    pub fn scale(a: Point, s: f64) -> Point {
        [a[0] * s, a[1] * s, a[2] * s]
    }
    /// Twice the area vector of triangle (a, b, c).
    #[inline]
    pub fn area2(a: Point, b: Point, c: Point) -> Point {
        cross(sub(b, a), sub(c, a))
    }
    /// Six times the signed volume of tetrahedron (a, b, c, d).
    #[inline]
    pub fn volume6(a: Point, b: Point, c: Point, d: Point) -> f64 {
        dot(sub(b, a), cross(sub(c, a), sub(d, a)))
    }
}
