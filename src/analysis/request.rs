//! The analysis requests: what a client can ask of a stored shape, one serde type shared by the CLI and the
//! service (the operator and solver specs, each analysis with its parameters and defaults).

use super::*;

/// Bumped whenever an analysis' numbers could change for the same request (part of job ids).
pub const ALGORITHM_VERSION: u32 = 3;

/// Which operator to build (see `kac_core::operators`).
#[derive(utoipa::ToSchema, Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(remote = "Self")]
#[serde(default, deny_unknown_fields)]
pub struct OperatorSpec {
    /// Default: by shape kind.
    pub operator: Option<OperatorKind>,
    /// Default: consistent for FEM operators, lumped for robust and point-cloud.
    pub mass: Option<Mass>,
    pub boundary: BoundarySpec,
    /// Dirichlet on these vertices (input numbering) instead of the shape's boundary.
    pub dirichlet_vertices: Option<Vec<u32>>,
    /// Point clouds: neighbours per point.
    pub neighbours: usize,
    /// Point clouds: heat-kernel time.
    pub time: Option<f64>,
    pub neighbourhood: Neighbourhood,
}

impl Default for OperatorSpec {
    fn default() -> Self {
        OperatorSpec {
            operator: None,
            mass: None,
            boundary: BoundarySpec::Neumann,
            dirichlet_vertices: None,
            neighbours: kac_core::operators::DEFAULT_NEIGHBOURS,
            time: None,
            neighbourhood: Neighbourhood::Radius,
        }
    }
}

#[derive(utoipa::ToSchema, Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize, Default)]
#[serde(rename_all = "snake_case")]
pub enum BoundarySpec {
    #[default]
    Neumann,
    Dirichlet,
}

/// Eigensolver parameters shared by every spectral analysis.
#[derive(utoipa::ToSchema, Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(remote = "Self")]
#[serde(default, deny_unknown_fields)]
pub struct SolverSpec {
    /// Relative residual tolerance (default 1e-10).
    pub tol: f64,
    /// Confirm by Sylvester's inertia (one LDLᵀ of L − τM) that no eigenvalue below the returned ones was missed,
    /// and solve again for any that were (default true; the result's `solver.completeness`). `false` skips the
    /// check: the result then says `completeness: null`.
    #[serde(skip_serializing_if = "is_true")]
    pub verify: bool,
}

pub(crate) fn is_true(b: &bool) -> bool {
    *b
}

impl Default for SolverSpec {
    fn default() -> Self {
        SolverSpec { tol: kac_core::spectrum::DEFAULT_TOL, verify: true }
    }
}

#[derive(utoipa::ToSchema, Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize, Default)]
#[serde(rename_all = "snake_case")]
pub enum HeatMethod {
    /// Σ e^{−λt} over the computed eigenpairs (with a truncation bound).
    #[default]
    Spectral,
    /// Backward Euler, (M + τL) u_{j+1} = M u_j, no eigenpairs.
    Implicit,
}

#[derive(utoipa::ToSchema, Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize, Default)]
#[serde(rename_all = "snake_case")]
pub enum EmbedScaling {
    /// Laplacian eigenmap: the eigenvectors themselves.
    #[default]
    None,
    /// Global point signature: φ/√λ.
    Gps,
}

/// One analysis of a shape. JSON: `{"analysis": "hks", "k": 100, "count": 50, ...}`.
#[derive(utoipa::ToSchema, Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(tag = "analysis", rename_all = "kebab-case")]
pub enum Analysis {
    /// The k smallest eigenpairs.
    Spectrum {
        #[serde(default = "k_default")]
        k: usize,
        /// Return the eigenvectors as a per-vertex array.
        #[serde(default)]
        eigenvectors: bool,
        #[serde(default)]
        operator: OperatorSpec,
        #[serde(default)]
        solver: SolverSpec,
    },
    /// Heat kernel signature (the scale-invariant form is its own analysis, `si-hks`).
    Hks {
        #[serde(default = "k_signature")]
        k: usize,
        #[serde(default)]
        options: HksOptions,
        #[serde(default)]
        operator: OperatorSpec,
        #[serde(default)]
        solver: SolverSpec,
    },
    /// Scale-invariant HKS (Bronstein & Kokkinos 2010): the Fourier moduli of the HKS on a log-time grid.
    SiHks {
        #[serde(default = "k_signature")]
        k: usize,
        #[serde(default)]
        options: SiHksOptions,
        #[serde(default)]
        operator: OperatorSpec,
        #[serde(default)]
        solver: SolverSpec,
    },
    Wks {
        #[serde(default = "k_signature")]
        k: usize,
        #[serde(default)]
        options: WksOptions,
        #[serde(default)]
        operator: OperatorSpec,
        #[serde(default)]
        solver: SolverSpec,
    },
    Gps {
        #[serde(default = "k_default")]
        k: usize,
        dimensions: Option<usize>,
        #[serde(default)]
        operator: OperatorSpec,
        #[serde(default)]
        solver: SolverSpec,
    },
    /// Shape-DNA and Weyl's-law estimates.
    ShapeDna {
        #[serde(default)]
        options: ShapeDnaOptions,
        #[serde(default)]
        operator: OperatorSpec,
        #[serde(default)]
        solver: SolverSpec,
    },
    /// Heat trace, and heat kernel rows / diffusion from source vertices.
    Heat {
        #[serde(default = "k_signature")]
        k: usize,
        /// Default: the HKS time grid with 10 times.
        times: Option<Vec<f64>>,
        #[serde(default)]
        sources: Vec<u32>,
        #[serde(default)]
        method: HeatMethod,
        /// Backward-Euler steps per time (implicit method).
        #[serde(default = "steps_default")]
        steps: usize,
        #[serde(default)]
        operator: OperatorSpec,
        #[serde(default)]
        solver: SolverSpec,
    },
    /// Geodesic distance from source vertices by the heat method (triangle meshes).
    Geodesic {
        sources: Vec<u32>,
        #[serde(default)]
        options: geodesic::HeatMethodOptions,
    },
    /// Spanning trees of the shape's edge graph (Kirchhoff).
    Trees {},
    /// Laplacian eigenmap / GPS coordinates, with the Fiedler vector and bisection.
    Embed {
        #[serde(default = "dimensions_default")]
        dimensions: usize,
        #[serde(default)]
        scaling: EmbedScaling,
        #[serde(default)]
        operator: OperatorSpec,
        #[serde(default)]
        solver: SolverSpec,
    },
    /// (M + αL) u = M ū for a per-vertex function ū (default: the vertex coordinates, i.e. implicit fairing).
    Smooth {
        alpha: f64,
        function: Option<Vec<f64>>,
        /// Keep ū on the shape's boundary (reproduces linear functions on flat meshes).
        #[serde(default)]
        fixed_boundary: bool,
        #[serde(default)]
        operator: OperatorSpec,
    },
    /// Harmonic interpolation of values given on some vertices, or semi-supervised labels.
    Interpolate {
        /// [vertex, value] pairs.
        #[serde(default)]
        #[schema(value_type = Vec<Vec<f64>>)]
        values: Vec<(u32, f64)>,
        /// [vertex, class] pairs (instead of values).
        #[serde(default)]
        #[schema(value_type = Vec<Vec<u32>>)]
        labels: Vec<(u32, u32)>,
        #[serde(default)]
        operator: OperatorSpec,
    },
}

pub(crate) fn k_default() -> usize {
    10
}
pub(crate) fn k_signature() -> usize {
    100
}
pub(crate) fn steps_default() -> usize {
    1
}
pub(crate) fn dimensions_default() -> usize {
    3
}

impl Analysis {
    pub fn name(&self) -> &'static str {
        match self {
            Analysis::Spectrum { .. } => "spectrum",
            Analysis::Hks { .. } => "hks",
            Analysis::SiHks { .. } => "si-hks",
            Analysis::Wks { .. } => "wks",
            Analysis::Gps { .. } => "gps",
            Analysis::ShapeDna { .. } => "shape-dna",
            Analysis::Heat { .. } => "heat",
            Analysis::Geodesic { .. } => "geodesic",
            Analysis::Trees { .. } => "trees",
            Analysis::Embed { .. } => "embed",
            Analysis::Smooth { .. } => "smooth",
            Analysis::Interpolate { .. } => "interpolate",
        }
    }
}
