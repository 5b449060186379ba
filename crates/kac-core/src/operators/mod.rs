//! Discrete Laplace operators: a sparse symmetric pair (L, M), L positive semidefinite (stiffness), M the
//! positive definite mass, on every kind of shape, with Neumann (natural) or Dirichlet boundary conditions.
//! Each operator's file states its formula, sign and units. No I/O, no HTTP.

pub mod boundary;
pub mod cotan_laplacian;
pub mod denoise;
pub(crate) mod error;
pub mod graph_laplacian;
pub mod intrinsic_delaunay;
pub mod manifold;
pub mod mass;
pub mod p2;
pub mod point_cloud;
pub mod polygon;
pub mod properties;
pub mod robust;
pub mod sparse;
pub mod tet_laplacian;

pub use error::OperatorError;
pub use mass::Mass;

use crate::geometry::{vec3, Point, Shape, ShapeKind};
use graph_laplacian::GraphKind;
use serde::{Deserialize, Serialize};
use sparse::SparsePair;
use std::sync::Arc;

/// The operators kac builds (CLI and API names in kebab-case).
#[cfg_attr(feature = "openapi", derive(utoipa::ToSchema))]
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum OperatorKind {
    /// Cotangent (P1 FEM) Laplacian of a triangle mesh.
    Cotan,
    /// Cotangent Laplacian of the intrinsic Delaunay triangulation (non-negative weights).
    IntrinsicDelaunay,
    /// Sharp & Crane's robust Laplacian: tufted cover, intrinsic Delaunay, mollification (non-manifold meshes,
    /// point clouds).
    Robust,
    /// Combinatorial graph Laplacian D − W.
    Graph,
    /// Symmetric normalized graph Laplacian I − D^{−1/2} W D^{−1/2}.
    GraphNormalized,
    /// Random-walk graph Laplacian, as (D − W) φ = λ D φ.
    GraphRandomWalk,
    /// Belkin–Niyogi heat-kernel point-cloud Laplacian.
    PointCloud,
    /// P1 FEM on a tetrahedral mesh.
    Tet,
    /// P1 FEM on a polyline (the 1-D string).
    String,
    /// Bunge et al.'s polygon Laplacian on the input's own polygons (quads, general polygons), no triangulation.
    Polygon,
}

impl OperatorKind {
    pub const ALL: [OperatorKind; 10] = [
        OperatorKind::Cotan,
        OperatorKind::IntrinsicDelaunay,
        OperatorKind::Robust,
        OperatorKind::Graph,
        OperatorKind::GraphNormalized,
        OperatorKind::GraphRandomWalk,
        OperatorKind::PointCloud,
        OperatorKind::Tet,
        OperatorKind::String,
        OperatorKind::Polygon,
    ];
    pub fn name(self) -> &'static str {
        match self {
            OperatorKind::Cotan => "cotan",
            OperatorKind::IntrinsicDelaunay => "intrinsic-delaunay",
            OperatorKind::Robust => "robust",
            OperatorKind::Graph => "graph",
            OperatorKind::GraphNormalized => "graph-normalized",
            OperatorKind::GraphRandomWalk => "graph-random-walk",
            OperatorKind::PointCloud => "point-cloud",
            OperatorKind::Tet => "tet",
            OperatorKind::String => "string",
            OperatorKind::Polygon => "polygon",
        }
    }
    pub fn from_name(s: &str) -> Option<Self> {
        Self::ALL.into_iter().find(|k| k.name() == s)
    }
    /// The default operator of a shape kind.
    pub fn default_for(kind: ShapeKind) -> Self {
        match kind {
            ShapeKind::TriangleMesh => OperatorKind::Cotan,
            ShapeKind::TetMesh => OperatorKind::Tet,
            ShapeKind::PointCloud => OperatorKind::PointCloud,
            ShapeKind::Graph => OperatorKind::Graph,
            ShapeKind::Polyline => OperatorKind::String,
        }
    }
    fn is_graph(self) -> bool {
        matches!(self, OperatorKind::Graph | OperatorKind::GraphNormalized | OperatorKind::GraphRandomWalk)
    }
    /// Whether the operator's pair can carry a dimension for Weyl's law, by which the eigensolver places its shift and
    /// plans spectrum slices: every operator but the graph Laplacians. A point cloud's pair has one where its intrinsic
    /// dimension is at most 3, which for points in Rⁿ beyond space only the points tell.
    pub fn has_weyl_dimension(self) -> bool {
        !self.is_graph()
    }
}

/// Boundary conditions.
#[derive(Debug, Clone, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Boundary {
    /// Natural (free) boundary: nothing is removed.
    Neumann,
    /// Zero on the shape's boundary (mesh boundary loops, tet boundary faces, polyline ends), by elimination.
    Dirichlet,
    /// Zero on the given vertices, by elimination.
    DirichletVertices(Vec<u32>),
}

impl Boundary {
    pub fn name(&self) -> &'static str {
        match self {
            Boundary::Neumann => "neumann",
            Boundary::Dirichlet | Boundary::DirichletVertices(_) => "dirichlet",
        }
    }
}

/// Which neighbours the point-cloud heat kernel sums over.
#[cfg_attr(feature = "openapi", derive(utoipa::ToSchema))]
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize, Default)]
#[serde(rename_all = "snake_case")]
pub enum Neighbourhood {
    /// All points within the kernel radius (default; the truncation is corrected exactly).
    #[default]
    Radius,
    /// The symmetrized k-nearest-neighbour graph (uniform sparsity); t defaults so the k-th neighbour sits near
    /// 3√t, and the truncation correction is that of r = 3√t (exact only where the k-th neighbour is there).
    Knn,
}

/// Parameters of the point-cloud and robust operators.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct CloudParams {
    /// Neighbours per point for spacing, normals and local areas, and for `Knn` neighbourhoods (default 16).
    pub k: usize,
    pub neighbourhood: Neighbourhood,
    /// Heat-kernel time t for every pair; default: per point, following the local spacing (about 5h² on a
    /// uniform sample, h the mean distance to the nearest neighbour; see [`point_cloud`]); with `Knn`
    /// neighbourhoods one time (d_k/3)².
    pub t: Option<f64>,
    /// Kernel support radius; default 3√t (6√t for the chapter's normalization).
    pub radius: Option<f64>,
    /// Intrinsic dimension m of the sampled manifold; default 2 for points in R³ (surfaces), estimated from the
    /// neighbourhoods for points in Rⁿ, n ≥ 4 ([`manifold`]).
    pub dimension: Option<usize>,
    pub normalization: manifold::CloudNormalization,
    /// Scanned clouds in R³: project the points onto a moving-least-squares surface first ([`denoise`]) where
    /// the neighbourhoods show noise (default true).
    pub denoise: bool,
}

/// Neighbours per point of the point-cloud operator unless asked otherwise (the one place this default is written:
/// the CLI and the service take it from here).
pub const DEFAULT_NEIGHBOURS: usize = 16;

impl Default for CloudParams {
    fn default() -> Self {
        CloudParams {
            k: DEFAULT_NEIGHBOURS,
            neighbourhood: Neighbourhood::Radius,
            t: None,
            radius: None,
            dimension: None,
            normalization: manifold::CloudNormalization::Symmetric,
            denoise: true,
        }
    }
}

/// What to build.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct OperatorOptions {
    /// Default: by shape kind (cotan, tet, point-cloud, graph, string).
    pub operator: Option<OperatorKind>,
    /// Default: consistent for FEM operators, lumped for robust and point-cloud; graphs use their own.
    pub mass: Option<Mass>,
    pub boundary: Boundary,
    pub cloud: CloudParams,
    /// Mollification factor of the robust Laplacian (δ relative to the mean edge length; default 1e-5).
    pub mollify: f64,
    /// Polynomial degree of the finite elements: 1 (default) or 2 ([`p2`]: `cotan` on triangle meshes, `tet`).
    pub order: u8,
    /// The input's polygons, in the shape's vertex numbering, for the `polygon` operator (`None`: the shape's
    /// triangles, where it is the cotan Laplacian).
    #[serde(skip)]
    pub polygons: Option<Arc<crate::geometry::Polygons>>,
    /// The input's middle nodes of curved edges (shape numbering), for quadratic elements (`None`: straight).
    #[serde(skip)]
    pub edge_nodes: Option<Arc<crate::geometry::EdgeNodes>>,
    /// Where quadratic elements put their edge nodes: the input's (`edge_nodes`) where it gives them, else on the
    /// straight edges (default); always straight; or, on a triangle mesh whose input gives none, on edges curved by
    /// the vertex normals ([`p2::midpoints_from_normals`]).
    pub midpoints: p2::Midpoints,
}

impl Default for OperatorOptions {
    fn default() -> Self {
        OperatorOptions {
            operator: None,
            mass: None,
            boundary: Boundary::Neumann,
            cloud: CloudParams::default(),
            mollify: 1e-5,
            order: 1,
            polygons: None,
            edge_nodes: None,
            midpoints: p2::Midpoints::Input,
        }
    }
}

/// A built operator: the pair on the kept vertices and how it was made.
#[derive(Debug, Clone)]
pub struct Operator {
    pub pair: SparsePair,
    pub kind: OperatorKind,
    pub mass: Mass,
    pub boundary: &'static str,
    /// Vertex count of the shape.
    pub full_size: usize,
    /// Kept vertices (sorted) when a Dirichlet boundary was eliminated; `None`: all vertices.
    pub interior: Option<Vec<u32>>,
    /// Parameters chosen automatically (point clouds: t, radius, h; robust: δ), echoed in results.
    pub parameters: serde_json::Map<String, serde_json::Value>,
    /// P2 elements: the edges whose midpoint unknowns follow the vertices' (`None`: one unknown per vertex).
    pub edge_unknowns: Option<Arc<Vec<[u32; 2]>>>,
}

impl Operator {
    /// Whether a Dirichlet condition removed unknowns (points dropped as outliers are removed too, without one).
    pub fn dirichlet(&self) -> bool {
        self.boundary == "dirichlet"
    }

    /// Unknowns before a Dirichlet elimination: the vertices, and the edges of P2 elements.
    pub fn unknowns(&self) -> usize {
        self.full_size + self.edge_unknowns.as_ref().map_or(0, |e| e.len())
    }

    /// Puts a vector of the (possibly condensed) operator back on all vertices, zeros on the Dirichlet boundary
    /// (P2: the values at the vertices; a P2 function's value at a vertex is its vertex unknown).
    pub fn expand(&self, x: &[f64]) -> Vec<f64> {
        let mut out = match &self.interior {
            None => x.to_vec(),
            Some(keep) => {
                // Zero on a Dirichlet boundary; no value (NaN) at points dropped as outliers.
                let fill = if self.dirichlet() { 0.0 } else { f64::NAN };
                let mut out = vec![fill; self.unknowns()];
                for (k, &i) in keep.iter().enumerate() {
                    out[i as usize] = x[k];
                }
                out
            }
        };
        out.truncate(self.full_size);
        out
    }

    /// A function given at the vertices as a vector over the operator's unknowns: P2 edge unknowns take the mean
    /// of their endpoints (the P1 interpolant, exact for linear functions); Dirichlet-eliminated ones are dropped.
    pub fn restrict(&self, per_vertex: &[f64]) -> Vec<f64> {
        let mut all = per_vertex.to_vec();
        if let Some(edges) = &self.edge_unknowns {
            all.extend(edges.iter().map(|e| 0.5 * (per_vertex[e[0] as usize] + per_vertex[e[1] as usize])));
        }
        match &self.interior {
            None => all,
            Some(keep) => keep.iter().map(|&i| all[i as usize]).collect(),
        }
    }
}

/// The points of a cloud the operator [`build`] would leave out as outliers (the point-cloud operator on a cloud in
/// R³ with the symmetric normalization and `denoise`: [`denoise::outliers`]), without building it: a caller that
/// needs every point in the operator (a correspondence maps vertices) can refuse before any eigensolve. Empty for
/// every other shape and operator.
pub fn dropped_points(shape: &Shape, options: &OperatorOptions) -> Result<Vec<usize>, OperatorError> {
    let cloud = &options.cloud;
    match (options.operator.unwrap_or_else(|| OperatorKind::default_for(shape.kind())), shape) {
        (OperatorKind::PointCloud, Shape::PointCloud(c))
            if cloud.denoise
                && c.ambient.is_none()
                && cloud.dimension.is_none_or(|m| m == 2)
                && cloud.normalization == manifold::CloudNormalization::Symmetric =>
        {
            let found = denoise::outliers(&c.points)?;
            Ok((0..found.flags.len()).filter(|&i| found.flags[i]).collect())
        }
        _ => Ok(vec![]),
    }
}

/// Builds the operator pair of a shape.
pub fn build(shape: &Shape, options: &OperatorOptions) -> Result<Operator, OperatorError> {
    let op = options.operator.unwrap_or_else(|| OperatorKind::default_for(shape.kind()));
    let not_applicable = || OperatorError::NotApplicable { operator: op.name(), kind: shape.kind().as_str() };
    let default_mass = match op {
        OperatorKind::Robust | OperatorKind::PointCloud => Mass::Lumped,
        OperatorKind::Graph | OperatorKind::GraphNormalized => Mass::Identity,
        OperatorKind::GraphRandomWalk => Mass::Degree,
        _ => Mass::Consistent,
    };
    let mass = options.mass.unwrap_or(default_mass);
    let mass_ok = match op {
        OperatorKind::Cotan | OperatorKind::IntrinsicDelaunay => {
            matches!(mass, Mass::Consistent | Mass::Lumped | Mass::Voronoi)
        }
        OperatorKind::Polygon => matches!(mass, Mass::Consistent | Mass::Lumped),
        OperatorKind::Tet | OperatorKind::String => matches!(mass, Mass::Consistent | Mass::Lumped),
        OperatorKind::Robust | OperatorKind::PointCloud => mass == Mass::Lumped,
        OperatorKind::Graph | OperatorKind::GraphNormalized => mass == Mass::Identity,
        OperatorKind::GraphRandomWalk => mass == Mass::Degree,
    };
    if !mass_ok {
        return Err(OperatorError::MassNotApplicable { operator: op.name(), mass: mass.name() });
    }
    let mut parameters = serde_json::Map::new();
    // Points of a cloud dropped as outliers: the operator is built on the others (kept, sorted).
    let mut kept_points: Option<Vec<u32>> = None;
    if options.order == 2 {
        return build_p2(shape, op, mass, options);
    } else if options.midpoints == p2::Midpoints::Normals {
        return Err(OperatorError::InvalidParameter {
            name: "midpoints",
            message: "edge midpoints place the nodes of quadratic elements: give order 2".into(),
        });
    } else if options.order != 1 {
        return Err(OperatorError::InvalidParameter {
            name: "order",
            message: format!("{}: the elements are linear (1) or quadratic (2)", options.order),
        });
    }
    let pair = match (op, shape) {
        (OperatorKind::Cotan, Shape::TriangleMesh(m)) => cotan_laplacian::cotan_pair(
            m.vertices.len(),
            &m.faces,
            |f| cotan_laplacian::face_lengths(&m.vertices, &m.faces[f]),
            mass,
        )?,
        (OperatorKind::Polygon, Shape::TriangleMesh(m)) => match &options.polygons {
            Some(polygons) => {
                parameters.insert("polygons".into(), polygons.len().into());
                polygon::polygon_pair(&m.vertices, polygons, mass)?
            }
            None => {
                parameters.insert("polygons".into(), "none kept: the mesh's triangles (the cotan Laplacian)".into());
                let mut tris = crate::geometry::Polygons::with_capacity(m.faces.len(), 3 * m.faces.len());
                for f in &m.faces {
                    tris.push(f);
                }
                polygon::polygon_pair(&m.vertices, &tris, mass)?
            }
        },
        (OperatorKind::IntrinsicDelaunay, Shape::TriangleMesh(m)) => {
            let (pair, flips) = intrinsic_delaunay::intrinsic_delaunay_pair(m, mass)?;
            parameters.insert("flips".into(), flips.into());
            pair
        }
        (OperatorKind::Robust, Shape::TriangleMesh(m)) => {
            let (pair, delta) = robust::robust_mesh_pair(m, options.mollify)?;
            parameters.insert("mollify_delta".into(), delta.into());
            pair
        }
        // The robust operator triangulates tangent planes in R³; points in Rⁿ have only the point-cloud operator.
        (OperatorKind::Robust, Shape::PointCloud(c)) if c.ambient.is_some() => return Err(not_applicable()),
        (OperatorKind::Robust, Shape::PointCloud(c)) => {
            let (pair, delta) = robust::robust_cloud_pair(&c.points, options.cloud.k, options.mollify)?;
            parameters.insert("mollify_delta".into(), delta.into());
            parameters.insert("k".into(), options.cloud.k.into());
            pair
        }
        (OperatorKind::PointCloud, s) => {
            let pts = s.positions().filter(|_| !matches!(s, Shape::Graph(_))).ok_or_else(not_applicable)?;
            let cloud = &options.cloud;
            let ambient = match s {
                Shape::PointCloud(c) => c.ambient.as_ref(),
                _ => None,
            };
            // Surfaces in R³ with local areas (the operator of `point_cloud`), unless the points lie in Rⁿ, the
            // intrinsic dimension is not 2, or the chapter's normalization is asked for.
            let general = ambient.is_some()
                || cloud.dimension.is_some_and(|m| m != 2)
                || cloud.normalization != manifold::CloudNormalization::Symmetric;
            let (pair, used) = if general {
                let flat: Vec<f64>;
                let points = match ambient {
                    Some(a) => manifold::Points { dim: a.dim, coords: &a.coords },
                    None => {
                        flat = pts.iter().flatten().copied().collect();
                        manifold::Points { dim: 3, coords: &flat }
                    }
                };
                manifold::manifold_pair(points, cloud)?
            } else {
                match s {
                    // A cloud (not a mesh's vertices) may be a noisy scan: denoised where its neighbourhoods say
                    // so (the finest scale being the flattest means there is no noise to remove).
                    Shape::PointCloud(c) if cloud.denoise => {
                        let found = denoise::outliers(pts)?;
                        let outlier = &found.flags;
                        let kept: Vec<u32> = (0..pts.len() as u32).filter(|&i| !outlier[i as usize]).collect();
                        let dropped: Vec<usize> = (0..pts.len()).filter(|&i| outlier[i]).collect();
                        parameters.insert(
                            "outliers".into(),
                            serde_json::json!({
                                "dropped": dropped.len(),
                                "examples": &dropped[..dropped.len().min(10)],
                                "threshold": found.threshold,
                                "isolated": found.isolated,
                                "clumps": found.clumps,
                                "clump_points": found.clump_points,
                                "clumps_kept": found.clumps_kept,
                                "rule": format!(
                                    "mean distance to the 16 nearest neighbours above 5 × its median over the cloud \
                                     (isolated); then pieces of the 16-nearest-neighbour graph within that distance \
                                     with fewer than {} points (clumps), unless such pieces hold more than {} % of \
                                     the points together (then they are the sampling, and kept: clumps_kept)",
                                    found.min_piece,
                                    denoise::MAX_CLUMP_SHARE * 100.0
                                ),
                            }),
                        );
                        let (sub, normals): (Vec<Point>, Option<Vec<Point>>) = if dropped.is_empty() {
                            (pts.to_vec(), c.normals.clone())
                        } else {
                            (
                                kept.iter().map(|&i| pts[i as usize]).collect(),
                                c.normals.as_ref().map(|ns| kept.iter().map(|&i| ns[i as usize]).collect()),
                            )
                        };
                        if !dropped.is_empty() {
                            kept_points = Some(kept);
                        }
                        let (projected, report) = denoise::denoise(&sub, normals.as_deref())?;
                        let applied = report.k > 16;
                        parameters
                            .insert("denoise".into(), serde_json::json!({ "applied": applied, "report": report }));
                        point_cloud::belkin_niyogi_pair(if applied { &projected } else { &sub }, cloud)?
                    }
                    _ => point_cloud::belkin_niyogi_pair(pts, cloud)?,
                }
            };
            parameters.extend(used);
            pair
        }
        (OperatorKind::Tet, Shape::TetMesh(m)) => tet_laplacian::tet_pair(&m.vertices, &m.tets, mass)?,
        (OperatorKind::String, Shape::Polyline(p)) => graph_laplacian::string_pair(&p.vertices, &p.segments, mass)?,
        (g, s) if g.is_graph() => {
            let kind = match g {
                OperatorKind::Graph => GraphKind::Combinatorial,
                OperatorKind::GraphNormalized => GraphKind::Normalized,
                _ => GraphKind::RandomWalk,
            };
            let (edges, weights) = edge_graph(s).ok_or_else(not_applicable)?;
            graph_laplacian::graph_pair(s.vertex_count(), &edges, &weights, kind)
        }
        _ => return Err(not_applicable()),
    };
    let full_size = shape.vertex_count().max(pair.n());
    let (pair, interior) =
        match kept_points {
            // Outliers dropped: the operator's unknowns are the kept points (a cloud has no boundary to fix).
            Some(kept) if options.boundary == Boundary::Neumann => (pair, Some(kept)),
            Some(_) => return Err(OperatorError::Boundary {
                message:
                    "a cloud with outliers dropped takes no Dirichlet vertices; give --no-denoise to keep every point"
                        .into(),
            }),
            None => boundary::apply(shape, pair, &options.boundary)?,
        };
    Ok(Operator {
        pair,
        kind: op,
        mass,
        boundary: options.boundary.name(),
        full_size,
        interior,
        parameters,
        edge_unknowns: None,
    })
}

/// Quadratic elements ([`p2`]): `cotan` on triangle meshes and `tet` on tet meshes, consistent mass only (a
/// lumped P2 mass has zero or negative vertex entries).
fn build_p2(shape: &Shape, op: OperatorKind, mass: Mass, options: &OperatorOptions) -> Result<Operator, OperatorError> {
    if mass != Mass::Consistent {
        return Err(OperatorError::InvalidParameter {
            name: "order",
            message: format!("quadratic elements take the consistent mass, not '{}'", mass.name()),
        });
    }
    // The input's curved edges where it gave their middle nodes (second-order elements) unless straight ones are
    // asked for, else straight ones or, when asked, edges curved by the vertex normals.
    let straight = |v: &[Point], [a, b]: [u32; 2]| vec3::scale(vec3::add(v[a as usize], v[b as usize]), 0.5);
    let file_nodes = match options.midpoints {
        p2::Midpoints::Straight => None,
        p2::Midpoints::Input | p2::Midpoints::Normals => options.edge_nodes.as_deref(),
    };
    let from_normals = match (options.midpoints, shape, file_nodes) {
        (p2::Midpoints::Normals, Shape::TriangleMesh(m), None) => Some(p2::midpoints_from_normals(m)),
        (p2::Midpoints::Normals, Shape::TriangleMesh(_), Some(_))
        | (p2::Midpoints::Straight | p2::Midpoints::Input, _, _) => None,
        (p2::Midpoints::Normals, _, _) => {
            return Err(OperatorError::InvalidParameter {
                name: "midpoints",
                message: format!(
                    "'normals' curves a triangle mesh's edges, not a {}'s (tet meshes take curved edges from \
                     second-order files)",
                    shape.kind().as_str()
                ),
            })
        }
    };
    let nodes = file_nodes.or(from_normals.as_ref());
    let (pair, edges) = match (op, shape) {
        (OperatorKind::Cotan, Shape::TriangleMesh(m)) => {
            let at = |e: [u32; 2]| nodes.and_then(|n| n.get(e)).unwrap_or_else(|| straight(&m.vertices, e));
            p2::triangle_p2_pair(&m.vertices, &m.faces, nodes.map(|_| &at as &(dyn Fn([u32; 2]) -> Point + Sync)))?
        }
        (OperatorKind::Tet, Shape::TetMesh(m)) => {
            let at = |e: [u32; 2]| nodes.and_then(|n| n.get(e)).unwrap_or_else(|| straight(&m.vertices, e));
            p2::tet_p2_pair(&m.vertices, &m.tets, nodes.map(|_| &at as &(dyn Fn([u32; 2]) -> Point + Sync)))?
        }
        _ => {
            return Err(OperatorError::InvalidParameter {
                name: "order",
                message: format!(
                "quadratic elements are built for 'cotan' on triangle meshes and 'tet' on tet meshes, not '{}' on a {}",
                op.name(),
                shape.kind().as_str()
            ),
            })
        }
    };
    let full_size = shape.vertex_count();
    let (pair, interior) = boundary::apply_p2(shape, pair, &edges, &options.boundary)?;
    let mut parameters = serde_json::Map::new();
    parameters.insert("order".into(), 2.into());
    parameters.insert("edge_unknowns".into(), edges.len().into());
    let midpoints = match nodes {
        Some(n) if from_normals.is_some() => format!(
            "curved by the vertex normals (angle-weighted; Hermite midpoints) on {} of {} edges",
            n.len(),
            edges.len()
        ),
        Some(n) => format!(
            "the input's middle nodes on {} of {} edges (isoparametric elements), the straight edges' midpoints \
             elsewhere",
            n.len(),
            edges.len()
        ),
        None => match options.edge_nodes.as_deref().filter(|_| options.midpoints == p2::Midpoints::Straight) {
            Some(n) => format!(
                "on the straight edges as asked (flat elements), the input's middle nodes on {} edges not used",
                n.len()
            ),
            None => "on the straight edges (flat elements: the input mesh's geometry)".into(),
        },
    };
    parameters.insert("midpoints".into(), midpoints.into());
    Ok(Operator {
        pair,
        kind: op,
        mass,
        boundary: options.boundary.name(),
        full_size,
        interior,
        parameters,
        edge_unknowns: Some(Arc::new(edges)),
    })
}

/// The edge graph of a shape with unit weights (graphs keep theirs); none for point clouds.
pub fn edge_graph(shape: &Shape) -> Option<(Vec<[u32; 2]>, Vec<f64>)> {
    let mut edges: Vec<[u32; 2]> = match shape {
        Shape::Graph(g) => return Some((g.edges.clone(), g.weights.clone())),
        Shape::PointCloud(_) => return None,
        Shape::Polyline(p) => p.segments.clone(),
        Shape::TriangleMesh(m) => m.faces.iter().flat_map(|f| [[f[0], f[1]], [f[1], f[2]], [f[2], f[0]]]).collect(),
        Shape::TetMesh(m) => m
            .tets
            .iter()
            .flat_map(|t| [[t[0], t[1]], [t[0], t[2]], [t[0], t[3]], [t[1], t[2]], [t[1], t[3]], [t[2], t[3]]])
            .collect(),
    };
    for e in edges.iter_mut() {
        if e[0] > e[1] {
            e.swap(0, 1);
        }
    }
    edges.sort_unstable();
    edges.dedup();
    let w = vec![1.0; edges.len()];
    Some((edges, w))
}
