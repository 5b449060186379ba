//! What each analysis returns, typed: one struct per analysis, the fields every result has ([`ResultHead`]), and
//! [`Summary`], their union tagged by `analysis`. The runner builds these and nothing else; the CLI prints them,
//! the service stores and serves them, and the OpenAPI document's `AnalysisResult` is their schema (one flat
//! `{Name}Result` per analysis under a discriminator), which the router tests hold every actual result to.

use super::*;
use kac_core::descriptors::curvature::{HeatCurvature, MeanCurvature};
use kac_core::descriptors::graph::{Fiedler, TreeCount};
use kac_core::descriptors::heat::{HeatContent, SpectralDiffusion};
use kac_core::descriptors::shape_dna::{Measures, ShapeDna};
use kac_core::descriptors::signatures::{Gps, Hks, SiHks, Wks};
use kac_core::descriptors::weyl::WeylEstimate;
use kac_core::geometry::grading::Corner;
use kac_core::operators::properties::PropertyReport;
use kac_core::pde::geodesic::{Geodesic, HeatMethodOptions};
use kac_core::pde::{Labels, Poisson};
use kac_core::spectrum::Completeness;
use utoipa::ToSchema;

/// A warning: a number outside its domain of validity (the codes are listed in the README).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, ToSchema)]
pub struct Warning {
    /// Stable code, e.g. `weyl-underresolved`.
    pub code: String,
    pub message: String,
}

impl Warning {
    pub fn new(code: &str, message: String) -> Self {
        Self { code: code.into(), message }
    }
}

/// The fields every analysis' result has (a comparison has its own: it names no one shape).
#[derive(Debug, Clone, Serialize, ToSchema)]
pub struct ResultHead {
    /// The shape analysed (its content hash).
    pub shape_id: String,
    /// The version of the algorithms that computed the numbers (a cached result of another version is not reused).
    pub algorithm_version: u32,
    /// Whether the eigenpairs came from the cache (no eigensolve for this result).
    pub eigenpairs_reused: bool,
    /// Numbers outside their domain of validity (empty when all is well).
    pub warnings: Vec<Warning>,
}

/// A result: the head and the analysis' own numbers, one JSON object tagged by `analysis`.
#[derive(Debug, Clone, Serialize)]
pub struct Typed {
    #[serde(flatten)]
    pub head: ResultHead,
    #[serde(flatten)]
    pub body: Summary,
}

/// The operator an analysis used: its kind, mass, boundary condition, number of unknowns and parameters.
#[derive(Debug, Clone, Serialize, ToSchema)]
pub struct OperatorUsed {
    /// The operator's kind (`cotan`, `graph`, `cloud`, …).
    pub operator: &'static str,
    /// `consistent` or `lumped`.
    pub mass: &'static str,
    /// `neumann` or `dirichlet` (the operator's; a Poisson problem also reports the condition it was solved with).
    pub boundary: &'static str,
    /// Unknowns: the matrices' order.
    pub size: usize,
    /// What the operator was built with, and what it found (a cloud's neighbourhoods, dimension, noise, …).
    #[schema(value_type = Object)]
    pub parameters: serde_json::Map<String, Value>,
}

impl OperatorUsed {
    pub fn of(op: &Operator) -> Self {
        Self {
            operator: op.kind.name(),
            mass: op.mass.name(),
            boundary: op.boundary,
            size: op.pair.n(),
            parameters: op.parameters.clone(),
        }
    }
}

/// Every analysis' own numbers, tagged by its name.
#[derive(Debug, Clone, Serialize, ToSchema)]
#[serde(tag = "analysis", rename_all = "kebab-case")]
pub enum Summary {
    Spectrum(Box<SpectrumSummary>),
    Operator(OperatorSummary),
    Hks(HksSummary),
    SiHks(SiHksSummary),
    Wks(WksSummary),
    Gps(GpsSummary),
    ShapeDna(ShapeDnaSummary),
    Fingerprint(FingerprintSummary),
    Heat(HeatSummary),
    Geodesic(GeodesicSummary),
    Gradient(GradientSummary),
    Divergence(DivergenceSummary),
    Trees(TreesSummary),
    MeanCurvature(MeanCurvatureSummary),
    HeatCurvature(HeatCurvatureSummary),
    Wave(WaveSummary),
    Schrodinger(SchrodingerSummary),
    Poisson(PoissonSummary),
    Diffuse(DiffuseSummary),
    DirichletEnergy(DirichletEnergySummary),
    Embed(EmbedSummary),
    Smooth(SmoothSummary),
    Interpolate(InterpolateSummary),
    Compare(CompareSummary),
    Correspondence(Box<super::correspond::CorrespondenceSummary>),
}

/// The eigensolver's report on a spectrum.
#[derive(Debug, Clone, Serialize, ToSchema)]
pub struct SolverReport {
    /// `dense`, `shift-invert block Lanczos`, … .
    pub method: &'static str,
    pub sigma: f64,
    pub block: usize,
    pub subspace: usize,
    pub restarts: usize,
    pub block_steps: usize,
    pub solves: usize,
    pub factor_nonzeros: usize,
    pub factorization: &'static str,
    /// Eigenvalues below the shift by Sylvester's inertia.
    pub below_sigma: Option<usize>,
    /// Connected components (each has a zero mode under Neumann conditions).
    pub components: Option<usize>,
    pub zero_modes: usize,
    pub completeness: Option<Completeness>,
    /// The relative residual tolerance.
    pub tol: f64,
    pub threads: usize,
    /// Spectrum slicing: each slice's window, shift, inertia, pairs and work (absent for a solve in one run; see
    /// `solver.slices` of the request).
    #[serde(skip_serializing_if = "Vec::is_empty")]
    pub slices: Vec<kac_core::spectrum::slicing::SliceReport>,
    /// The path the solve took where it is not the one planned (slices given up for one run, the Krylov method for
    /// the dense solver) and why; absent when it took the path planned. Such a result also carries the warning
    /// `solver-fallback`.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub plan: Option<kac_core::spectrum::PlanChange>,
}

/// Where a spectrum's seconds went.
#[derive(Debug, Clone, Serialize, ToSchema)]
pub struct SpectrumTimings {
    /// Reading the file (the CLI's; null in the service).
    pub read_s: Option<f64>,
    pub assembly_s: f64,
    pub symbolic_s: f64,
    pub numeric_s: f64,
    pub factorization_s: f64,
    pub iteration_s: f64,
    pub solve_s: f64,
    pub orthogonalize_s: f64,
    pub rayleigh_ritz_s: f64,
    pub restart_s: f64,
    pub verify_s: f64,
    pub total_s: f64,
}

/// The counting function N(λ) at each eigenvalue beside Weyl's law.
#[derive(Debug, Clone, Serialize, ToSchema)]
pub struct Counting {
    pub lambda: Vec<f64>,
    /// N(λ_i): eigenvalues at or below λ_i (a cluster counted together).
    pub count: Vec<usize>,
    pub cluster_tolerance: f64,
    /// Weyl's law at each λ_i (null for a graph, or above dimension 3).
    pub weyl: Option<Vec<f64>>,
    pub dimension: Option<u8>,
    pub measure: Option<f64>,
    pub boundary_measure: Option<f64>,
    /// The terms of Weyl's law used.
    pub terms: &'static str,
}

/// One level of an extrapolation: a refinement and its eigenvalues.
#[derive(Debug, Clone, Serialize, ToSchema)]
pub struct ExtrapolationLevel {
    pub unknowns: usize,
    pub eigenvalues: Vec<f64>,
    pub completeness: Option<Completeness>,
    pub seconds: f64,
}

/// A corner the refinements were graded toward, with its vertex in the upload's numbering.
#[derive(Debug, Clone, Serialize, ToSchema)]
pub struct GradedCorner {
    /// The corner's vertex in the upload's numbering.
    pub vertex: Option<usize>,
    pub angle_degrees: f64,
    /// π / angle: the singular eigenfunctions' exponent at the corner.
    pub exponent: f64,
    pub radius: f64,
    pub beta: f64,
}

impl GradedCorner {
    pub fn of(c: &Corner, vertex: Option<usize>) -> Self {
        Self { vertex, angle_degrees: c.angle_degrees, exponent: c.exponent, radius: c.radius, beta: c.beta }
    }
}

/// Whether the refinements were graded toward corners, and why not.
#[derive(Debug, Clone, Serialize, ToSchema)]
pub struct GradingReport {
    pub graded: bool,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub reason: Option<String>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub corners: Option<Vec<GradedCorner>>,
}

/// Richardson extrapolation of the eigenvalues over uniform (or graded) refinements.
#[derive(Debug, Clone, Serialize, ToSchema)]
pub struct Extrapolation {
    pub refinements: usize,
    /// What the limit is the spectrum of.
    pub domain: &'static str,
    pub nominal_order: f64,
    pub eigenvalues: Vec<f64>,
    pub error_estimate: Vec<f64>,
    pub observed_order: Vec<Option<f64>>,
    pub order_used: Vec<f64>,
    pub levels: Vec<ExtrapolationLevel>,
    pub grading: GradingReport,
    /// How many of a curved (P2) input's curved edge nodes the refinements left out (they fit the first level only).
    pub curved_edges_ignored: Option<usize>,
    pub method: &'static str,
}

/// `spectrum`: the k smallest eigenpairs of L φ = λ M φ (or those in a band), with the solver's report.
#[derive(Debug, Clone, Serialize, ToSchema)]
pub struct SpectrumSummary {
    pub k: usize,
    /// The band [a, b] asked for, if any.
    pub band: Option<[f64; 2]>,
    /// How `residuals` are measured.
    pub residual_norm: &'static str,
    pub sign_convention: &'static str,
    /// The eigenvalues, ascending (the extrapolated ones when `eigenvalues_source` is `extrapolation`).
    pub eigenvalues: Vec<f64>,
    pub residuals: Vec<f64>,
    /// Where the eigenvectors are: the array name (the CLI: the file written); null when not asked for.
    pub eigenvectors: Option<String>,
    pub solver: SolverReport,
    pub timings: SpectrumTimings,
    /// Whether the k returned are the k smallest (Sylvester's inertia), also under `solver`.
    pub completeness: Option<Completeness>,
    /// `mesh` or `extrapolation`.
    pub eigenvalues_source: &'static str,
    /// The input mesh's own eigenvalues, where `eigenvalues` are extrapolated.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub mesh_eigenvalues: Option<Vec<f64>>,
    /// The extrapolated eigenvalues' error estimates.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub error_estimate: Option<Vec<f64>>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub extrapolation: Option<Extrapolation>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub counting: Option<Counting>,
    #[serde(flatten)]
    pub operator: OperatorUsed,
}

/// The operator's matrices: how they are numbered and stored.
#[derive(Debug, Clone, Serialize, ToSchema)]
pub struct MatricesInfo {
    pub numbering: &'static str,
    pub stiffness: MatrixInfo,
    pub mass: MatrixInfo,
    pub triplets: &'static str,
}

#[derive(Debug, Clone, Serialize, ToSchema)]
pub struct MatrixInfo {
    /// `L` or `M`.
    pub name: &'static str,
    pub nonzeros_upper: usize,
}

#[derive(Debug, Clone, Serialize, ToSchema)]
pub struct AssemblyTimings {
    pub assembly_s: f64,
}

/// `operator`: the operator's size and sparsity, its property report, its matrices.
#[derive(Debug, Clone, Serialize, ToSchema)]
pub struct OperatorSummary {
    pub kind: kac_core::ShapeKind,
    pub vertices: usize,
    pub unknowns: usize,
    pub nonzeros: usize,
    pub mass_is_diagonal: bool,
    pub sign: &'static str,
    pub timings: AssemblyTimings,
    /// The "no free lunch" properties (when `report` was asked).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub properties: Option<PropertyReport>,
    /// The matrices (when `matrices` was asked).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub matrices: Option<MatricesInfo>,
    #[serde(flatten)]
    pub operator: OperatorUsed,
}

/// `hks`: the heat kernel signature per vertex (the array `hks`, a column per time).
#[derive(Debug, Clone, Serialize, ToSchema)]
pub struct HksSummary {
    pub k: usize,
    pub hks: Hks,
    pub options: HksOptions,
    #[serde(flatten)]
    pub operator: OperatorUsed,
}

/// `si-hks`: the scale-invariant HKS per vertex (the array `si_hks`, a column per frequency).
#[derive(Debug, Clone, Serialize, ToSchema)]
pub struct SiHksSummary {
    pub k: usize,
    pub si_hks: SiHks,
    pub options: SiHksOptions,
    #[serde(flatten)]
    pub operator: OperatorUsed,
}

/// `wks`: the wave kernel signature per vertex (the array `wks`, a column per energy).
#[derive(Debug, Clone, Serialize, ToSchema)]
pub struct WksSummary {
    pub k: usize,
    pub wks: Wks,
    pub options: WksOptions,
    #[serde(flatten)]
    pub operator: OperatorUsed,
}

/// `gps`: the global point signature per vertex (the array `gps`, a column per eigenvalue).
#[derive(Debug, Clone, Serialize, ToSchema)]
pub struct GpsSummary {
    pub k: usize,
    pub gps: Gps,
    #[serde(flatten)]
    pub operator: OperatorUsed,
}

/// `shape-dna`: the normalized eigenvalue sequence, Weyl's estimates and the shape's measures.
#[derive(Debug, Clone, Serialize, ToSchema)]
pub struct ShapeDnaSummary {
    pub shape_dna: ShapeDna,
    pub weyl: Option<WeylEstimate>,
    pub measures: Measures,
    pub options: ShapeDnaOptions,
    pub residuals: Vec<f64>,
    #[serde(flatten)]
    pub operator: OperatorUsed,
}

/// `fingerprint`: each family's values as the search index keeps them.
#[derive(Debug, Clone, Serialize, ToSchema)]
pub struct FingerprintSummary {
    pub options: FingerprintOptions,
    /// Shape-DNA in full (its values are the `shape-dna` family's).
    pub shape_dna: ShapeDna,
    /// One entry per family: shape-dna, heat-distribution, gps-d2.
    pub families: Vec<FamilyValues>,
    /// The shape's measure (area, volume or length: the mass matrix's total) the families were scaled by.
    pub measure: f64,
    #[serde(flatten)]
    pub operator: OperatorUsed,
}

/// One family's fingerprint of a shape.
#[derive(Debug, Clone, Serialize, ToSchema)]
pub struct FamilyValues {
    /// shape-dna, heat-distribution or gps-d2.
    pub descriptor: &'static str,
    /// The family: a search by these options looks in it.
    pub family: String,
    /// Non-zero eigenpairs it was computed from (GPS: its dimensions).
    pub eigenpairs: usize,
    pub values: Vec<f64>,
}

/// A source of the spectral heat kernel and what truncation can miss of its flow.
#[derive(Debug, Clone, Serialize, ToSchema)]
pub struct HeatSource {
    /// The source vertex (the upload's numbering).
    pub source: u32,
    /// At each time, a bound on what the k pairs miss of the flow of the hat function at the source.
    pub hat_function_truncation_bound: Vec<f64>,
}

/// The sources of a `heat` result: with their truncation bounds (spectral) or as vertices (implicit).
#[derive(Debug, Clone, Serialize, ToSchema)]
#[serde(untagged)]
pub enum HeatSources {
    Spectral(Vec<HeatSource>),
    Implicit(Vec<u32>),
}

/// `heat`: the heat kernel k_t(source, ·) per source (an array `heat_kernel` each) and the heat trace.
#[derive(Debug, Clone, Serialize, ToSchema)]
pub struct HeatSummary {
    /// `spectral` or `implicit`.
    pub method: HeatMethod,
    pub times: Vec<f64>,
    pub sources: HeatSources,
    /// What the arrays are (`heat_kernel`, one per source; the name `arrays` is the service's map of them).
    pub kernel_arrays: &'static str,
    /// Pairs used (spectral).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub k: Option<usize>,
    /// Backward Euler steps per interval (implicit).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub steps: Option<usize>,
    /// The heat trace Σ e^{−λt} (spectral).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub heat_trace: Option<Vec<f64>>,
    /// A bound on what the k pairs miss of the discrete heat trace (spectral): truncation only, the same values as
    /// `heat_trace_truncation_bound` (kept under this name for earlier clients).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub heat_trace_tail_bound: Option<Vec<f64>>,
    /// A bound, per time, on what the k pairs miss of the discrete heat trace Σ e^{−λt} over every eigenvalue of the
    /// mesh's operator (spectral). It bounds truncation only: the mesh's eigenvalues differ from the surface's by
    /// the discretization error (O(h²) for P1), which it does not cover (see `heat_trace_error`).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub heat_trace_truncation_bound: Option<Vec<f64>>,
    /// What the heat trace's bound covers, in words (spectral).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub heat_trace_error: Option<&'static str>,
    /// The heat content Q(t) = ∫ u(t) from u₀ = 1 (spectral, Dirichlet conditions).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub heat_content: Option<HeatContent>,
    #[serde(flatten)]
    pub operator: OperatorUsed,
}

/// `geodesic`: distances from the sources by the heat method (the array `distance`).
#[derive(Debug, Clone, Serialize, ToSchema)]
pub struct GeodesicSummary {
    pub geodesic: Geodesic,
    pub options: HeatMethodOptions,
    pub max_distance: f64,
    /// The columns of `distance`: `heat_method`, and `varadhan` when asked.
    pub columns: Vec<&'static str>,
    /// `cotan`.
    pub operator: &'static str,
    /// `lumped`.
    pub mass: &'static str,
}

/// Minimum, maximum, mean and count of the finite values of a per-vertex quantity (null where none is finite).
#[derive(Debug, Clone, Serialize, ToSchema)]
pub struct FiniteStats {
    pub min: Option<f64>,
    pub max: Option<f64>,
    pub mean: Option<f64>,
    /// Vertices with a finite value.
    pub vertices: usize,
}

impl FiniteStats {
    pub fn of(x: &[f64]) -> Self {
        let f: Vec<f64> = x.iter().copied().filter(|v| v.is_finite()).collect();
        let n = f.len();
        let some = |v: f64| (n > 0).then_some(v);
        Self {
            min: some(f.iter().copied().fold(f64::INFINITY, f64::min)),
            max: some(f.iter().copied().fold(f64::NEG_INFINITY, f64::max)),
            mean: some(f.iter().sum::<f64>() / n.max(1) as f64),
            vertices: n,
        }
    }
}

/// `gradient`: the gradient of a P1 function per element (the array `gradient`).
#[derive(Debug, Clone, Serialize, ToSchema)]
pub struct GradientSummary {
    pub elements: usize,
    pub gradient_norm: FiniteStats,
    pub rows: &'static str,
    pub definition: &'static str,
}

/// `divergence`: the divergence of a per-element field per vertex (the array `divergence`).
#[derive(Debug, Clone, Serialize, ToSchema)]
pub struct DivergenceSummary {
    /// `integrated`, `pointwise`.
    pub columns: Vec<&'static str>,
    pub definition: &'static str,
    /// The mass the pointwise column is taken over: `lumped` (the default) or `voronoi`.
    pub mass: &'static str,
    /// What the pointwise value is, for this mass.
    pub meaning: &'static str,
}

/// `trees`: the number of spanning trees (Kirchhoff's matrix-tree theorem).
#[derive(Debug, Clone, Serialize, ToSchema)]
pub struct TreesSummary {
    pub trees: TreeCount,
}

/// `mean-curvature`: mean curvature, normals and the angle defect per vertex.
#[derive(Debug, Clone, Serialize, ToSchema)]
pub struct MeanCurvatureSummary {
    pub mean_curvature: FiniteStats,
    pub gaussian_curvature: FiniteStats,
    pub method: MeanCurvature,
    pub convention: &'static str,
}

/// `heat-curvature`: the Gaussian curvature read from the heat kernel's short-time expansion.
#[derive(Debug, Clone, Serialize, ToSchema)]
pub struct HeatCurvatureSummary {
    pub k: usize,
    pub heat_curvature: FiniteStats,
    pub fit: HeatCurvature,
    /// Boundary vertices (no value: the expansion has a boundary term there).
    pub boundary_vertices: usize,
    /// The smallest time the mesh resolves (20 × the mean area per vertex).
    pub resolved_time: f64,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub boundary_note: Option<&'static str>,
    /// The angle defect, for comparison (triangle meshes).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub gaussian_curvature: Option<FiniteStats>,
    #[serde(flatten)]
    pub operator: OperatorUsed,
}

/// How an evolution's initial data was given: per vertex, or a Gaussian bump about a source.
#[derive(Debug, Clone, Serialize, ToSchema)]
pub struct InitialGiven {
    /// `per vertex`, when given as a function.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub given: Option<&'static str>,
    /// The bump's centre.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub source: Option<u32>,
    /// The bump's width.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub width: Option<f64>,
}

/// `wave`: the wave equation's solution at each time (the array `wave`) and its energy.
#[derive(Debug, Clone, Serialize, ToSchema)]
pub struct WaveSummary {
    pub k: usize,
    pub times: Vec<f64>,
    pub initial: InitialGiven,
    /// The M-norm of the initial data outside the basis.
    pub dropped_m_norm: f64,
    /// Whether an initial velocity was given.
    pub velocity: bool,
    pub energy: Vec<f64>,
    pub energy_relative_drift: f64,
    pub equation: &'static str,
    #[serde(flatten)]
    pub operator: OperatorUsed,
}

/// `schrodinger`: ψ(t) (the arrays `schrodinger_re`, `schrodinger_im`) and its conserved norm.
#[derive(Debug, Clone, Serialize, ToSchema)]
pub struct SchrodingerSummary {
    pub k: usize,
    pub times: Vec<f64>,
    pub initial: InitialGiven,
    pub m_norm: Vec<f64>,
    pub dropped_m_norm: f64,
    pub equation: &'static str,
    #[serde(flatten)]
    pub operator: OperatorUsed,
}

/// `poisson`: the solution of Δf = g (the array `solution`).
#[derive(Debug, Clone, Serialize, ToSchema)]
pub struct PoissonSummary {
    pub poisson: Poisson,
    pub equation: &'static str,
    /// The condition the problem was solved with (`neumann`, `dirichlet`, `values`, …); the operator's own is
    /// `operator_boundary`.
    pub boundary: &'static str,
    pub operator_boundary: &'static str,
    pub operator: &'static str,
    pub mass: &'static str,
    pub size: usize,
    #[schema(value_type = Object)]
    pub parameters: serde_json::Map<String, Value>,
}

/// `diffuse`: a function diffused to each time (the array `diffused`).
#[derive(Debug, Clone, Serialize, ToSchema)]
pub struct DiffuseSummary {
    pub times: Vec<f64>,
    pub diffusivity: f64,
    pub method: HeatMethod,
    pub initial: InitialGiven,
    /// The spectral solution's report (spectral).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub spectral: Option<SpectralDiffusion>,
    /// The times αt the unit-diffusivity solution was taken at (spectral).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub scaled_times: Option<Vec<f64>>,
    /// Backward Euler steps (implicit).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub steps: Option<usize>,
    #[serde(flatten)]
    pub operator: OperatorUsed,
}

/// The Dirichlet energy of one function.
#[derive(Debug, Clone, Serialize, ToSchema)]
pub struct Energy {
    /// `function`, or a coordinate `x`, `y`, `z`.
    pub of: String,
    pub energy: f64,
    pub u_m_u: f64,
    pub rayleigh_quotient: Option<f64>,
}

/// `dirichlet-energy`: ½ uᵀLu of a function, or of each coordinate.
#[derive(Debug, Clone, Serialize, ToSchema)]
pub struct DirichletEnergySummary {
    pub dirichlet_energy: Vec<Energy>,
    pub definition: &'static str,
    #[serde(flatten)]
    pub operator: OperatorUsed,
}

/// `embed`: the Laplacian eigenmap (the array `embedding`) and the Fiedler vector's split (the array `fiedler`).
#[derive(Debug, Clone, Serialize, ToSchema)]
pub struct EmbedSummary {
    pub dimensions: usize,
    pub scaling: EmbedScaling,
    pub eigenvalues: Vec<f64>,
    pub fiedler: Option<Fiedler>,
    pub components: usize,
    pub sign_convention: &'static str,
    #[serde(flatten)]
    pub operator: OperatorUsed,
}

/// `smooth`: (M + αL) u = M ū for a function or the coordinates (the array `smoothed`).
#[derive(Debug, Clone, Serialize, ToSchema)]
pub struct SmoothSummary {
    pub alpha: f64,
    /// `function` or `coordinates`.
    pub smoothed: &'static str,
    pub fixed_boundary: bool,
    pub equation: &'static str,
    #[serde(flatten)]
    pub operator: OperatorUsed,
}

/// `interpolate`: harmonic interpolation of values (the array `interpolated`) or labels (`labels`, `scores`).
#[derive(Debug, Clone, Serialize, ToSchema)]
pub struct InterpolateSummary {
    pub method: &'static str,
    /// Vertices with a given value (values).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub known: Option<usize>,
    /// The classes and their sizes (labels).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub labels: Option<Labels>,
    #[serde(flatten)]
    pub operator: OperatorUsed,
}

/// A shape a comparison could not fingerprint, with its problem.
#[derive(Debug, Clone, Serialize, ToSchema)]
pub struct CompareFailure {
    pub shape_id: String,
    /// The problem's code.
    pub code: String,
    pub status: u16,
    pub detail: String,
}

/// A neighbour in a comparison.
#[derive(Debug, Clone, Serialize, ToSchema)]
pub struct CompareNeighbour {
    pub shape_id: String,
    pub distance: f64,
}

/// A shape's nearest neighbours in a comparison.
#[derive(Debug, Clone, Serialize, ToSchema)]
pub struct CompareNearest {
    pub shape_id: String,
    pub nearest: Vec<CompareNeighbour>,
}

/// `compare`: distances between shapes by shape-DNA and each shape's nearest neighbours.
#[derive(Debug, Clone, Serialize, ToSchema)]
pub struct CompareSummary {
    /// What `distances` and `nearest` are by: `fused`, `shape-dna`, `heat-distribution` or `gps-d2`.
    pub descriptor: &'static str,
    pub options: ShapeDnaOptions,
    pub metric: &'static str,
    pub operator: OperatorSpec,
    /// The shapes compared (those fingerprinted), in the order of `fingerprints` and `distances`.
    pub shape_ids: Vec<String>,
    pub fingerprints: Vec<Vec<f64>>,
    /// By `descriptor`.
    pub distances: Vec<Vec<f64>>,
    pub nearest: Vec<CompareNearest>,
    /// Each family's distances (a comparison by `fused` or by a family other than shape-DNA computes every
    /// family; empty for a comparison by shape-DNA, whose distances are `distances`).
    pub families: Vec<CompareFamily>,
    pub failures: Vec<CompareFailure>,
    pub algorithm_version: u32,
    /// Always empty: a comparison's numbers are the shape-DNA's.
    pub warnings: Vec<Warning>,
}

/// One family's distances in a comparison.
#[derive(Debug, Clone, Serialize, ToSchema)]
pub struct CompareFamily {
    /// shape-dna, heat-distribution or gps-d2.
    pub descriptor: &'static str,
    pub family: String,
    /// Its weight in the fused distance.
    pub weight: f64,
    /// Its spread over the shapes compared (the root-mean-square distance between their fingerprints), which the
    /// fused distance divides its distances by.
    pub spread: f64,
    /// Between the shapes compared, in the order of `shape_ids`.
    pub distances: Vec<Vec<f64>>,
}

impl Summary {
    /// The parameters of the operator a result used, where it names one.
    pub(crate) fn operator_parameters(&self) -> Option<&serde_json::Map<String, Value>> {
        Some(match self {
            Summary::Spectrum(s) => &s.operator.parameters,
            Summary::Operator(s) => &s.operator.parameters,
            Summary::Hks(s) => &s.operator.parameters,
            Summary::SiHks(s) => &s.operator.parameters,
            Summary::Wks(s) => &s.operator.parameters,
            Summary::Gps(s) => &s.operator.parameters,
            Summary::ShapeDna(s) => &s.operator.parameters,
            Summary::Fingerprint(s) => &s.operator.parameters,
            Summary::Heat(s) => &s.operator.parameters,
            Summary::HeatCurvature(s) => &s.operator.parameters,
            Summary::Wave(s) => &s.operator.parameters,
            Summary::Schrodinger(s) => &s.operator.parameters,
            Summary::Poisson(s) => &s.parameters,
            Summary::Diffuse(s) => &s.operator.parameters,
            Summary::DirichletEnergy(s) => &s.operator.parameters,
            Summary::Embed(s) => &s.operator.parameters,
            Summary::Smooth(s) => &s.operator.parameters,
            Summary::Interpolate(s) => &s.operator.parameters,
            Summary::Geodesic(_)
            | Summary::Gradient(_)
            | Summary::Divergence(_)
            | Summary::Trees(_)
            | Summary::MeanCurvature(_)
            | Summary::Compare(_) => return None,
            Summary::Correspondence(s) => &s.operator.parameters,
        })
    }
}
