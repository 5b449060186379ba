//! The option types the analysis requests share: the operator and the solver (each the service's JSON object and
//! the CLI's flags), the initial data of the evolution equations, and their choices.

use super::*;
use kac_core::descriptors::shape_dna::{Normalization, Reweighting};
use kac_core::operators::manifold::CloudNormalization;
use kac_core::operators::p2::Midpoints;

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

/// A family of retrieval fingerprints (each a fixed-length vector the search index holds), or their fusion.
#[derive(utoipa::ToSchema, Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize, Deserialize, Default)]
#[serde(rename_all = "kebab-case")]
pub enum Descriptor {
    /// The families' distances, each divided by its spread over the collection, weighted and summed
    /// ([`FUSION_WEIGHTS`]); the default, measured best on the retrieval benchmark (docs/retrieval.md).
    #[default]
    Fused,
    /// Shape-DNA: the normalized, reweighted eigenvalues.
    ShapeDna,
    /// The distribution of the heat kernel signature over the shape at fixed times of the shape scaled to unit
    /// measure (`kac_core::descriptors::global::heat_distribution`).
    HeatDistribution,
    /// The distribution of distances between points in the global point signature embedding (GPS D2,
    /// `kac_core::descriptors::global::gps_d2`).
    GpsD2,
}

impl Descriptor {
    /// The families a fingerprint job computes, in this order everywhere (results, weights, compare).
    pub const FAMILIES: [Descriptor; 3] = [Descriptor::ShapeDna, Descriptor::HeatDistribution, Descriptor::GpsD2];
    pub fn name(self) -> &'static str {
        match self {
            Descriptor::Fused => "fused",
            Descriptor::ShapeDna => "shape-dna",
            Descriptor::HeatDistribution => "heat-distribution",
            Descriptor::GpsD2 => "gps-d2",
        }
    }
    /// The families a search or comparison by this descriptor reads.
    pub fn members(self) -> &'static [Descriptor] {
        match self {
            Descriptor::Fused => &Self::FAMILIES,
            Descriptor::ShapeDna => &Self::FAMILIES[0..1],
            Descriptor::HeatDistribution => &Self::FAMILIES[1..2],
            Descriptor::GpsD2 => &Self::FAMILIES[2..3],
        }
    }
    /// A family's weight in the fused distance ([`FUSION_WEIGHTS`]); 1 alone.
    pub fn weight(self) -> f64 {
        match self {
            Descriptor::Fused => 1.0,
            Descriptor::ShapeDna => FUSION_WEIGHTS[0],
            Descriptor::HeatDistribution => FUSION_WEIGHTS[1],
            Descriptor::GpsD2 => FUSION_WEIGHTS[2],
        }
    }
}

/// The weights of shape-DNA, the heat distribution and GPS D2 in the fused distance (each family's distance first
/// divided by its spread over the collection), chosen on the retrieval benchmark (`bench/retrieval.py`, figures and
/// caveats in docs/retrieval.md): on a grid of steps of 0.05, the best class-level mAP among the weights whose
/// non-rigid mAP reaches 0.99. Shape-DNA ranks poses best, the heat distribution classes: heavier heat weights
/// rank the class-level collection better and poses worse.
pub const FUSION_WEIGHTS: [f64; 3] = [0.7, 0.1, 0.2];

/// The fingerprint a retrieval request computes or looks up, with retrieval's defaults: 50 non-zero eigenpairs,
/// shape-DNA normalized by the shape's measure (`geometry`) and reweighted by index, so that every family is
/// invariant to the shape's scale (the defaults that measure best on the retrieval benchmark; shape-DNA's own
/// analysis keeps its defaults, the raw eigenvalues).
#[derive(utoipa::ToSchema, clap::Args, Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(remote = "Self")]
#[serde(default, deny_unknown_fields)]
pub struct FingerprintOptions {
    /// Shape-DNA's values, and the non-zero eigenpairs the other families are computed from (default 50).
    #[arg(short = 'k', long = "k", default_value_t = FingerprintOptions::default().k)]
    pub k: usize,
    /// Shape-DNA reports the zero modes too (default false).
    #[arg(long)]
    pub include_zero: bool,
    /// Shape-DNA's normalization (default geometry: by the area of a surface, the volume of a solid).
    #[arg(long, default_value_t = FingerprintOptions::default().normalization, value_parser = Normalization::parse)]
    pub normalization: Normalization,
    /// Shape-DNA's reweighting (default index).
    #[arg(long, default_value_t = FingerprintOptions::default().reweighting, value_parser = Reweighting::parse)]
    pub reweighting: Reweighting,
}
kac_core::object_only_serde!(FingerprintOptions);

impl Default for FingerprintOptions {
    fn default() -> Self {
        FingerprintOptions {
            k: 50,
            include_zero: false,
            normalization: Normalization::Geometry,
            reweighting: Reweighting::Index,
        }
    }
}

impl FingerprintOptions {
    /// The shape-DNA these options ask for.
    pub fn dna(&self) -> ShapeDnaOptions {
        ShapeDnaOptions {
            k: self.k,
            include_zero: self.include_zero,
            normalization: self.normalization,
            reweighting: self.reweighting,
        }
    }
    /// Options asking for the given shape-DNA.
    pub fn of_dna(dna: &ShapeDnaOptions) -> Self {
        FingerprintOptions {
            k: dna.k,
            include_zero: dna.include_zero,
            normalization: dna.normalization,
            reweighting: dna.reweighting,
        }
    }
}
