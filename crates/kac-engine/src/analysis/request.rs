//! The analysis requests: what a client can ask of a stored shape, one serde type shared by the CLI and the
//! service (the operator and solver specs, each analysis with its parameters and defaults).

use super::*;
use kac_core::operators::manifold::CloudNormalization;
use kac_core::operators::p2::Midpoints;

/// Bumped whenever an analysis' numbers could change for the same request (part of job ids).
pub const ALGORITHM_VERSION: u32 = 10;

/// Bumped whenever a fingerprint's values could change for the same shape-DNA options and operator (part of the
/// fingerprint family, so that stored fingerprints stay comparable across versions that change other numbers
/// only). Version 10 of the analyses changed Weyl estimates, heat curvature's window and result fields, not
/// shape-DNA's values.
pub const FINGERPRINT_VERSION: u32 = 9;

/// Which operator to build (see `kac_core::operators`): one type for the service's `operator` object and the
/// CLI's operator flags (`--operator`, `--mass`, `--boundary`, `--dirichlet-vertices`, `--neighbours`, `--time`,
/// `--neighbourhood`), so both take the same options with the same defaults.
#[derive(utoipa::ToSchema, clap::Args, Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(remote = "Self")]
#[serde(default, deny_unknown_fields)]
pub struct OperatorSpec {
    /// cotan, intrinsic-delaunay, robust, graph, graph-normalized, graph-random-walk, point-cloud, tet, string, polygon
    /// (default: by shape kind).
    #[arg(long = "operator", value_parser = parse_operator)]
    pub operator: Option<OperatorKind>,
    /// consistent, lumped, voronoi (default: consistent for FEM operators, lumped for robust and point-cloud).
    #[arg(long, value_parser = parse_mass)]
    pub mass: Option<Mass>,
    /// neumann (default) or dirichlet (the shape's boundary).
    #[arg(long, value_enum, default_value_t = BoundarySpec::Neumann)]
    pub boundary: BoundarySpec,
    /// Dirichlet on these vertices instead of the shape's boundary (indices in the input file's numbering; the
    /// CLI takes them comma-separated).
    #[arg(long, value_delimiter = ',')]
    pub dirichlet_vertices: Option<Vec<u32>>,
    /// Point clouds: neighbours per point.
    #[arg(long, default_value_t = kac_core::operators::DEFAULT_NEIGHBOURS)]
    pub neighbours: usize,
    /// Point clouds: heat-kernel time t for every pair (default: surfaces in R³ a time per point following the
    /// local spacing, about 5h² on a uniform sample, h the mean nearest-neighbour distance; in Rⁿ one (2h)²).
    #[arg(long)]
    pub time: Option<f64>,
    /// Point clouds: sum the heat kernel over `radius` (ε-ball, default) or `knn` (k nearest) neighbourhoods.
    #[arg(long, default_value = "radius", value_parser = parse_neighbourhood)]
    pub neighbourhood: Neighbourhood,
    /// Point clouds: the kernel's radius ε (default 3√t; 6√t with the chapter's normalization).
    #[serde(skip_serializing_if = "Option::is_none")]
    #[arg(long)]
    pub radius: Option<f64>,
    /// Point clouds: the intrinsic dimension m of the sampled manifold (default 2 for points in R³, in either
    /// normalization; estimated from the neighbourhoods (Levina–Bickel) for points in Rⁿ, n ≥ 4, and refused when
    /// the estimate is not within 0.2 of an integer).
    #[serde(skip_serializing_if = "Option::is_none")]
    #[arg(long)]
    pub intrinsic_dimension: Option<usize>,
    /// Point clouds: `symmetric` (local volumes as quadrature weights, truncation corrected; default) or
    /// `chapter` (eq. 9.39: uniform weights vol/K). The CLI's flag is `--cloud-normalization`.
    #[serde(skip_serializing_if = "is_symmetric")]
    #[arg(id = "cloud_normalization", long = "cloud-normalization", default_value = "symmetric", value_parser = parse_normalization)]
    pub normalization: CloudNormalization,
    /// Finite elements of degree 1 (default) or 2: quadratic (P2) elements for `cotan` on triangle meshes and
    /// `tet`, with an unknown at every edge's midpoint (consistent mass only); eigenvalues converge as O(h⁴) on
    /// flat domains. Per-vertex outputs are the values at the vertices.
    #[serde(skip_serializing_if = "is_one")]
    #[arg(long, default_value_t = 1)]
    pub order: u8,
    /// Where order 2 puts its edge nodes: `input` (default: a second-order file's middle nodes where it gives them,
    /// curving the elements, else the straight edges' midpoints), `straight` (always the straight edges: flat
    /// elements, the polyhedron's spectrum, whatever the file gives) or, on a triangle mesh whose file gives no
    /// edge nodes, edges curved by the vertex `normals` (a smooth surface's estimate; not for meshes with sharp
    /// creases, whose averaged normals would round them). Only `normals` is refused with order 1.
    #[serde(skip_serializing_if = "is_input")]
    #[arg(long, default_value = "input", value_parser = parse_midpoints)]
    pub midpoints: Midpoints,
    /// Point clouds in R³: project the points onto a moving-least-squares surface before building the operator
    /// where their neighbourhoods show noise (default true; the CLI's `--no-denoise` turns it off). The scale,
    /// the noise level and how far points moved are reported under `parameters.denoise`.
    #[serde(skip_serializing_if = "is_true")]
    #[arg(long = "no-denoise", action = clap::ArgAction::SetFalse)]
    pub denoise: bool,
}

fn is_one(o: &u8) -> bool {
    *o == 1
}

fn is_symmetric(n: &CloudNormalization) -> bool {
    *n == CloudNormalization::Symmetric
}

fn is_input(m: &Midpoints) -> bool {
    *m == Midpoints::Input
}

fn parse_midpoints(s: &str) -> Result<Midpoints, String> {
    match s {
        "input" => Ok(Midpoints::Input),
        "straight" => Ok(Midpoints::Straight),
        "normals" => Ok(Midpoints::Normals),
        _ => Err(format!("unknown midpoints '{s}'; one of: input, straight, normals")),
    }
}

fn parse_normalization(s: &str) -> Result<CloudNormalization, String> {
    match s {
        "symmetric" => Ok(CloudNormalization::Symmetric),
        "chapter" => Ok(CloudNormalization::Chapter),
        _ => Err(format!("unknown point-cloud normalization '{s}'; one of: symmetric, chapter")),
    }
}

fn parse_operator(s: &str) -> Result<OperatorKind, String> {
    OperatorKind::from_name(s)
        .ok_or_else(|| format!("unknown operator '{s}'; one of: {}", OperatorKind::ALL.map(|k| k.name()).join(", ")))
}

pub fn parse_mass(s: &str) -> Result<Mass, String> {
    match Mass::from_name(s) {
        Some(m @ (Mass::Consistent | Mass::Lumped | Mass::Voronoi)) => Ok(m),
        _ => Err(format!("unknown mass '{s}'; one of: consistent, lumped, voronoi")),
    }
}

fn parse_neighbourhood(s: &str) -> Result<Neighbourhood, String> {
    match s {
        "radius" => Ok(Neighbourhood::Radius),
        "knn" => Ok(Neighbourhood::Knn),
        _ => Err(format!("unknown neighbourhood '{s}'; one of: radius, knn")),
    }
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
            radius: None,
            intrinsic_dimension: None,
            normalization: CloudNormalization::Symmetric,
            order: 1,
            midpoints: Midpoints::Input,
            denoise: true,
        }
    }
}

#[derive(utoipa::ToSchema, clap::ValueEnum, Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize, Default)]
#[serde(rename_all = "snake_case")]
pub enum BoundarySpec {
    #[default]
    Neumann,
    Dirichlet,
}

/// Eigensolver parameters shared by every spectral analysis: one type for the service's `solver` object and the
/// CLI's solver flags (`--tol`, `--no-verify`, `--method`, `--sigma`, `--block`, `--subspace`). Only `tol` and
/// `verify` can change the numbers beyond the tolerance; the rest choose how they are computed.
#[derive(utoipa::ToSchema, clap::Args, Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(remote = "Self")]
#[serde(default, deny_unknown_fields)]
pub struct SolverSpec {
    /// Relative residual tolerance (default 1e-10).
    #[arg(long, default_value_t = kac_core::spectrum::DEFAULT_TOL)]
    pub tol: f64,
    /// Request field `verify` (default true): confirm by Sylvester's inertia (one LDLᵀ of L − τM) that no
    /// eigenvalue below the returned ones was missed, and solve again for any that were (the result's
    /// `solver.completeness`).
    #[serde(skip_serializing_if = "is_true")]
    #[arg(
        long = "no-verify",
        action = clap::ArgAction::SetFalse,
        help = "Skip the completeness check by Sylvester's inertia (one LDLᵀ factorization fewer); the result then \
                says completeness: null and may miss eigenvalues"
    )]
    pub verify: bool,
    /// auto (default), dense (every eigenpair of the dense pencil; the service takes it while unknowns² is within
    /// --max-output-values) or sparse (shift-invert block Lanczos). The CLI's flag is `--solver-method`
    /// (`kac spectrum` also takes `--method`; `kac heat --method` chooses spectral or implicit).
    #[serde(skip_serializing_if = "is_auto")]
    #[arg(id = "solver_method", long = "solver-method", value_enum, default_value_t = SolverMethod::Auto)]
    pub method: SolverMethod,
    /// Shift σ of the shift-invert solver: below the spectrum (σ < 0) L − σM is factored by Cholesky, inside it
    /// by LDLᵀ (default: inside, at 0.7 × Weyl's estimate of λ_k, for meshes, curves and point clouds with k ≥ 8;
    /// −mean(L_ii/M_ii)/n for graphs and small k).
    #[serde(skip_serializing_if = "Option::is_none")]
    #[arg(long, allow_hyphen_values = true)]
    pub sigma: Option<f64>,
    /// Tuning of the sparse solver: right-hand sides per block solve (default 8; 1 to 64).
    #[serde(skip_serializing_if = "Option::is_none")]
    #[arg(long)]
    pub block: Option<usize>,
    /// Tuning of the sparse solver: Krylov basis columns kept between restarts (default max(2w, w + 6b,
    /// min(3w, w + 100)) for w = k + max(b/2, 2); at least w + 2b). The service counts the basis, unknowns ×
    /// columns, against --max-output-values.
    #[serde(skip_serializing_if = "Option::is_none")]
    #[arg(long)]
    pub subspace: Option<usize>,
    /// Spectrum slicing: the interval [0, λ_k] cut into this many slices by Weyl's law, each solved around its own
    /// shift with its own factorization, the slices in parallel on the threads given (default: one run below 400
    /// pairs, then one slice per 125 pairs; 1 solves in one run; 1 to 64). The result's `solver.slices` says what
    /// each did.
    #[serde(skip_serializing_if = "Option::is_none")]
    #[arg(long)]
    pub slices: Option<usize>,
}

pub(crate) fn is_true(b: &bool) -> bool {
    *b
}

fn is_auto(m: &SolverMethod) -> bool {
    *m == SolverMethod::Auto
}

impl Default for SolverSpec {
    fn default() -> Self {
        SolverSpec {
            tol: kac_core::spectrum::DEFAULT_TOL,
            verify: true,
            method: SolverMethod::Auto,
            sigma: None,
            block: None,
            subspace: None,
            slices: None,
        }
    }
}

impl SolverSpec {
    /// The core's options for k pairs (threads from the caller).
    pub fn eigen_options(&self, k: usize, threads: usize) -> EigenOptions {
        EigenOptions {
            k,
            tol: self.tol,
            threads,
            verify: self.verify,
            method: match self.method {
                SolverMethod::Auto => spectrum::Method::Auto,
                SolverMethod::Dense => spectrum::Method::Dense,
                SolverMethod::Sparse => spectrum::Method::Sparse,
            },
            sigma: self.sigma,
            block: self.block,
            subspace: self.subspace,
            slices: self.slices,
            ..Default::default()
        }
    }
}

/// Initial data of an evolution: a function per vertex (the upload's numbering), or a Gaussian bump
/// exp(−d²/(2w²)) of width w around a source vertex (d the straight-line distance to its position).
#[derive(utoipa::ToSchema, Debug, Clone, PartialEq, Serialize, Deserialize, Default)]
pub struct InitialData {
    /// u₀ (or Re ψ₀) per vertex, in the upload's numbering.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub initial: Option<Vec<f64>>,
    /// Or a bump at this vertex (upload numbering).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub source: Option<u32>,
    /// The bump's width w (default: 5 % of the bounding box's diagonal).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub width: Option<f64>,
}

/// Which eigensolver runs.
#[derive(utoipa::ToSchema, clap::ValueEnum, Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize, Default)]
#[serde(rename_all = "snake_case")]
pub enum SolverMethod {
    /// Dense for small problems (or components), sparse otherwise.
    #[default]
    Auto,
    Dense,
    Sparse,
}

#[derive(utoipa::ToSchema, clap::ValueEnum, Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize, Default)]
#[serde(rename_all = "snake_case")]
pub enum HeatMethod {
    /// Σ e^{−λt} over the computed eigenpairs (with a truncation bound).
    #[default]
    Spectral,
    /// Backward Euler, (M + τL) u_{j+1} = M u_j, no eigenpairs.
    Implicit,
}

#[derive(utoipa::ToSchema, clap::ValueEnum, Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize, Default)]
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
    /// The k smallest eigenpairs (or, with `band`, every pair with λ in [a, b]).
    Spectrum {
        #[serde(default = "k_default")]
        k: usize,
        /// Every eigenpair with λ in [a, b] instead of the k smallest (k is then ignored); the service caps the
        /// count at --max-k and the eigenvectors at --max-output-values.
        #[serde(default, skip_serializing_if = "Option::is_none")]
        band: Option<[f64; 2]>,
        /// Return the eigenvectors as a per-vertex array.
        #[serde(default)]
        eigenvectors: bool,
        /// Add the counting function N(λ) at each returned eigenvalue beside Weyl's law for the shape's measure
        /// (two terms where the boundary's measure is known).
        #[serde(default, skip_serializing_if = "std::ops::Not::not")]
        counting: bool,
        /// Continuum eigenvalues with error bars: solve again on `refinements` refinements of the mesh (each
        /// triangle into four, each tet into eight; graded toward the corners that limit the order unless
        /// `grading` is false) and extrapolate (Richardson, at the observed order), for flat triangle meshes and
        /// tet meshes. Not with `band`.
        #[serde(default, skip_serializing_if = "std::ops::Not::not")]
        extrapolate: bool,
        /// Refinements for `extrapolate` (only with it): 1 (two levels, the nominal order) to 3 (default 2: three
        /// levels, the order observed).
        #[serde(default = "refinements_default", skip_serializing_if = "is_two")]
        refinements: usize,
        /// With `extrapolate` on a flat triangle mesh (only with it): grade every level toward the domain's corners
        /// that limit the order (re-entrant ones; with order 2 also those above 90°, whose r^{π/ω} singularity caps
        /// P2), radially, element size ∝ r^{1−α/p} for a corner of exponent α = π/ω, which restores the nominal
        /// order there (default true; false: uniform levels).
        #[serde(default = "yes", skip_serializing_if = "is_true")]
        grading: bool,
        #[serde(default)]
        operator: OperatorSpec,
        #[serde(default)]
        solver: SolverSpec,
    },
    /// The operator itself: L and M as downloadable matrices (Matrix Market, SciPy .npz; kept as upper-triangle
    /// triplets), the map from its unknowns to the upload's vertices, and on request the "no free lunch" property
    /// report.
    Operator {
        /// Add the property report (symmetry, locality, linear precision, maximum principle, PSD, null space).
        #[serde(default)]
        report: bool,
        /// Return L and M (`stiffness`, `mass`) and the unknowns' vertices (default true).
        #[serde(default = "yes", skip_serializing_if = "is_true")]
        matrices: bool,
        #[serde(default)]
        operator: OperatorSpec,
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
    /// Mean curvature H and the outward unit normal per vertex from M⁻¹LX = 2Hn (cotan stiffness, mixed Voronoi
    /// area; triangle meshes), with the angle-defect Gaussian curvature beside it; boundary vertices flagged.
    MeanCurvature {},
    /// Gaussian curvature heard from the heat kernel: K(x) from 4πt·k_t(x,x) = 1 + tK/3 + O(t²) fitted over a
    /// window of small times, from the k smallest eigenpairs; the angle-defect K beside it on triangle meshes.
    HeatCurvature {
        #[serde(default = "k_curvature")]
        k: usize,
        /// The window's times (default: 8 log-spaced from the larger of 4 ln 10 / λ_k and the mesh's resolution
        /// time, up to 4× that but kept at or below the curvature scale 1/κ_max², never less than 2×).
        #[serde(default, skip_serializing_if = "Option::is_none")]
        times: Option<Vec<f64>>,
        #[serde(default)]
        operator: OperatorSpec,
        #[serde(default)]
        solver: SolverSpec,
    },
    /// The wave equation ∂²u/∂t² = −Δu by modal superposition over the k smallest eigenpairs, from an initial
    /// displacement (`initial`, per vertex in the upload's numbering, or a Gaussian bump of `width` at `source`)
    /// and an optional initial velocity.
    Wave {
        #[serde(default = "k_signature")]
        k: usize,
        times: Vec<f64>,
        #[serde(flatten)]
        start: InitialData,
        /// ∂u/∂t at t = 0, per vertex (upload numbering; default zero).
        #[serde(default, skip_serializing_if = "Option::is_none")]
        velocity: Option<Vec<f64>>,
        #[serde(default)]
        operator: OperatorSpec,
        #[serde(default)]
        solver: SolverSpec,
    },
    /// The Schrödinger equation ∂ψ/∂t = −iΔψ, unitary in the eigenbasis: ψ(t) = Σ e^{−iλt}⟨ψ₀, φ⟩_M φ over the k
    /// smallest eigenpairs; real and imaginary parts as arrays, the M-norm at every time reported (conserved).
    Schrodinger {
        #[serde(default = "k_signature")]
        k: usize,
        times: Vec<f64>,
        #[serde(flatten)]
        start: InitialData,
        /// The imaginary part of ψ₀, per vertex (upload numbering; default zero).
        #[serde(default, skip_serializing_if = "Option::is_none")]
        initial_imag: Option<Vec<f64>>,
        #[serde(default)]
        operator: OperatorSpec,
        #[serde(default)]
        solver: SolverSpec,
    },
    /// Poisson's equation Δf = g (L f = M g): Neumann (the mean of g that makes it incompatible is removed per
    /// component and reported; f has mean zero) or with Dirichlet values on given vertices.
    Poisson {
        /// g per vertex (upload numbering).
        g: Vec<f64>,
        /// f fixed at these vertices (upload numbering): `[[vertex, value], …]`; none: Neumann.
        #[serde(default, skip_serializing_if = "Option::is_none")]
        #[schema(value_type = Option<Vec<Vec<f64>>>)]
        dirichlet_values: Option<Vec<(u32, f64)>>,
        #[serde(default)]
        operator: OperatorSpec,
    },
    /// Heat diffusion ∂u/∂t = −αΔu of a given function (or a bump at a source vertex): spectral over the k
    /// smallest eigenpairs with the truncation bound, or backward Euler.
    Diffuse {
        times: Vec<f64>,
        #[serde(flatten)]
        start: InitialData,
        /// The diffusivity α (default 1): u(t) is the unit-diffusivity solution at αt.
        #[serde(default = "one")]
        diffusivity: f64,
        #[serde(default)]
        method: HeatMethod,
        #[serde(default = "k_signature")]
        k: usize,
        /// Backward-Euler steps per time (`implicit`).
        #[serde(default = "steps_default")]
        steps: usize,
        #[serde(default)]
        operator: OperatorSpec,
        #[serde(default)]
        solver: SolverSpec,
    },
    /// The Dirichlet energy ½ uᵀLu of a function (default: of each coordinate), with uᵀMu and the Rayleigh
    /// quotient uᵀLu / uᵀMu.
    DirichletEnergy {
        /// u per vertex (upload numbering); absent: the vertex coordinates, one energy each.
        #[serde(default, skip_serializing_if = "Option::is_none")]
        function: Option<Vec<f64>>,
        #[serde(default)]
        operator: OperatorSpec,
    },
    /// The gradient of a per-vertex function on each element (triangle or tetrahedron; Prop. 9.2): constant per
    /// element, Σ u_i ∇φ_i. Rows of the `gradient` array: the validated mesh's elements in order.
    Gradient {
        /// u per vertex (upload numbering).
        function: Vec<f64>,
    },
    /// The divergence of a per-element vector field (Def. 9.1) per vertex: integrated, (div X)_i = −Σ_f |f|
    /// X_f·∇φ_i (so that div ∇u = −L u), and pointwise: the integrated divergence divided by the vertex's mass
    /// (`mass`: its share of the area or volume).
    Divergence {
        /// One vector [x, y, z] per element of the validated mesh, in its order (as `gradient` returns them).
        field: Vec<[f64; 3]>,
        /// The mass the pointwise divergence is taken over: lumped (default; a third of each incident triangle, a
        /// quarter of each incident tetrahedron) or voronoi (triangle meshes: the mixed Voronoi areas, the cells the
        /// cotan Laplacian integrates over, exact for div ∇x² on uniform grids where lumped is not).
        #[serde(default, skip_serializing_if = "Option::is_none")]
        mass: Option<Mass>,
    },
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

pub fn k_default() -> usize {
    10
}
pub fn k_signature() -> usize {
    100
}
pub fn refinements_default() -> usize {
    2
}
fn is_two(r: &usize) -> bool {
    *r == 2
}
pub(crate) fn yes() -> bool {
    true
}
pub fn one() -> f64 {
    1.0
}
pub fn k_curvature() -> usize {
    300
}
pub fn steps_default() -> usize {
    1
}
pub fn dimensions_default() -> usize {
    3
}

impl Analysis {
    pub fn name(&self) -> &'static str {
        match self {
            Analysis::Spectrum { .. } => "spectrum",
            Analysis::Operator { .. } => "operator",
            Analysis::Hks { .. } => "hks",
            Analysis::SiHks { .. } => "si-hks",
            Analysis::Wks { .. } => "wks",
            Analysis::Gps { .. } => "gps",
            Analysis::ShapeDna { .. } => "shape-dna",
            Analysis::Heat { .. } => "heat",
            Analysis::Geodesic { .. } => "geodesic",
            Analysis::Trees { .. } => "trees",
            Analysis::MeanCurvature { .. } => "mean-curvature",
            Analysis::HeatCurvature { .. } => "heat-curvature",
            Analysis::Wave { .. } => "wave",
            Analysis::Schrodinger { .. } => "schrodinger",
            Analysis::Poisson { .. } => "poisson",
            Analysis::Diffuse { .. } => "diffuse",
            Analysis::DirichletEnergy { .. } => "dirichlet-energy",
            Analysis::Embed { .. } => "embed",
            Analysis::Gradient { .. } => "gradient",
            Analysis::Divergence { .. } => "divergence",
            Analysis::Smooth { .. } => "smooth",
            Analysis::Interpolate { .. } => "interpolate",
        }
    }

    /// Options that only mean something together: `refinements` and `grading` with `extrapolate`, which takes
    /// the k smallest pairs (not a `band`) on 1 to 3 refinements. Checked at submission and again before a run,
    /// so that no option is silently ignored.
    pub fn check_options(&self) -> Result<(), AnalysisError> {
        if let Analysis::Spectrum { band, extrapolate, refinements, grading, .. } = self {
            if *extrapolate {
                if band.is_some() {
                    return Err(AnalysisError::invalid_parameter("extrapolate takes the k smallest pairs, not a band"));
                }
                if !(1..=3).contains(refinements) {
                    return Err(AnalysisError::invalid_parameter(format!(
                        "refinements = {refinements}: give 1, 2 or 3"
                    )));
                }
            } else if *refinements != refinements_default() || !*grading {
                return Err(AnalysisError::invalid_parameter(
                    "`refinements` and `grading` set how `extrapolate` refines; give them with `extrapolate: true`",
                ));
            }
        }
        Ok(())
    }

    /// The operator an analysis builds, where it takes one.
    pub fn operator_spec(&self) -> Option<&OperatorSpec> {
        match self {
            Analysis::Spectrum { operator, .. }
            | Analysis::Operator { operator, .. }
            | Analysis::Hks { operator, .. }
            | Analysis::SiHks { operator, .. }
            | Analysis::Wks { operator, .. }
            | Analysis::Gps { operator, .. }
            | Analysis::ShapeDna { operator, .. }
            | Analysis::Heat { operator, .. }
            | Analysis::HeatCurvature { operator, .. }
            | Analysis::Wave { operator, .. }
            | Analysis::Schrodinger { operator, .. }
            | Analysis::Poisson { operator, .. }
            | Analysis::Diffuse { operator, .. }
            | Analysis::DirichletEnergy { operator, .. }
            | Analysis::Embed { operator, .. }
            | Analysis::Smooth { operator, .. }
            | Analysis::Interpolate { operator, .. } => Some(operator),
            Analysis::Geodesic { .. }
            | Analysis::Trees { .. }
            | Analysis::MeanCurvature { .. }
            | Analysis::Gradient { .. }
            | Analysis::Divergence { .. } => None,
        }
    }

    /// Whether the analysis solves an eigenproblem (whose every phase sees the stop flag); the others factor or
    /// assemble in single calls.
    pub fn solves_eigenpairs(&self) -> bool {
        match self {
            Analysis::Heat { method, .. } | Analysis::Diffuse { method, .. } => *method == HeatMethod::Spectral,
            other => other.solver().is_some(),
        }
    }

    /// The eigensolver settings of an analysis that solves for eigenpairs.
    pub fn solver(&self) -> Option<&SolverSpec> {
        match self {
            Analysis::Spectrum { solver, .. }
            | Analysis::Hks { solver, .. }
            | Analysis::SiHks { solver, .. }
            | Analysis::Wks { solver, .. }
            | Analysis::Gps { solver, .. }
            | Analysis::ShapeDna { solver, .. }
            | Analysis::Heat { solver, .. }
            | Analysis::HeatCurvature { solver, .. }
            | Analysis::Wave { solver, .. }
            | Analysis::Schrodinger { solver, .. }
            | Analysis::Diffuse { solver, .. }
            | Analysis::Embed { solver, .. } => Some(solver),
            Analysis::Gradient { .. }
            | Analysis::Divergence { .. }
            | Analysis::Operator { .. }
            | Analysis::Geodesic { .. }
            | Analysis::Trees { .. }
            | Analysis::MeanCurvature { .. }
            | Analysis::Poisson { .. }
            | Analysis::DirichletEnergy { .. }
            | Analysis::Smooth { .. }
            | Analysis::Interpolate { .. } => None,
        }
    }
}
