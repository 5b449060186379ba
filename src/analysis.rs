//! Analyses: what a client can ask of a stored shape, as one serde type shared by the CLI subcommands and the
//! service's job API. Each analysis names its operator, solver and descriptor parameters; [`run`] computes it
//! from a validated shape (reusing cached eigenpairs through [`SpectrumCache`]) and returns a JSON summary that
//! echoes every parameter plus the per-vertex arrays, kept apart so that they can be written as `.npy` or shown
//! as colours.
//!
//! Vertex indices in requests and rows of per-vertex arrays follow the numbering of the uploaded file (welded
//! input vertices share their value; vertices validation dropped get NaN).

use kac_core::descriptors::graph::{components, eigenmap, fiedler, spanning_trees};
use kac_core::descriptors::heat::{diffuse_spectral, heat_kernel_row, heat_trace, heat_trace_tail_bound};
use kac_core::descriptors::shape_dna::{self, Measures, ShapeDnaOptions};
use kac_core::descriptors::signatures::{self, HksOptions, SiHksOptions, WksOptions};
use kac_core::descriptors::weyl::weyl_estimate;
use kac_core::descriptors::{Basis, DescriptorError};
use kac_core::operators::{self, Boundary, CloudParams, Mass, Neighbourhood, Operator, OperatorKind, OperatorOptions};
use kac_core::pde::{self, geodesic};
use kac_core::spectrum::{self, Control, EigenOptions, Spectrum};
use kac_core::{Shape, Validated};
use serde::{Deserialize, Serialize};
use serde_json::{json, Value};
use std::sync::Arc;

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
            neighbours: 16,
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

fn is_true(b: &bool) -> bool {
    *b
}

impl Default for SolverSpec {
    fn default() -> Self {
        SolverSpec { tol: 1e-10, verify: true }
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

fn k_default() -> usize {
    10
}
fn k_signature() -> usize {
    100
}
fn steps_default() -> usize {
    1
}
fn dimensions_default() -> usize {
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

/// Why an analysis failed: one variant per kind, the core's errors kept whole. Its code and whether the request
/// was at fault come from exhaustive matches (a new variant anywhere must say both).
#[derive(Debug, Clone, PartialEq)]
pub enum AnalysisError {
    /// A parameter of the request is out of its range (`invalid-parameter`).
    InvalidParameter(String),
    /// k = 0, or more eigenpairs than unknowns (`invalid-k`).
    InvalidK(String),
    /// The analysis does not apply to this kind of shape (`not-applicable`).
    NotApplicable(String),
    Operator(operators::OperatorError),
    Eigen(spectrum::EigenError),
    Descriptor(DescriptorError),
}

impl AnalysisError {
    pub fn invalid_parameter(message: impl Into<String>) -> Self {
        AnalysisError::InvalidParameter(message.into())
    }
    pub fn invalid_k(message: impl Into<String>) -> Self {
        AnalysisError::InvalidK(message.into())
    }
    pub fn not_applicable(message: impl Into<String>) -> Self {
        AnalysisError::NotApplicable(message.into())
    }
    /// The stable problem code.
    pub fn code(&self) -> &'static str {
        match self {
            AnalysisError::InvalidParameter(_) => "invalid-parameter",
            AnalysisError::InvalidK(_) => "invalid-k",
            AnalysisError::NotApplicable(_) => "not-applicable",
            AnalysisError::Operator(e) => e.code(),
            AnalysisError::Eigen(e) => e.code(),
            AnalysisError::Descriptor(e) => e.code(),
        }
    }
    /// The request cannot succeed as given (4xx); otherwise a computation failed (5xx / failed job).
    pub fn caller_fault(&self) -> bool {
        match self {
            AnalysisError::InvalidParameter(_) | AnalysisError::InvalidK(_) | AnalysisError::NotApplicable(_) => true,
            AnalysisError::Operator(e) => e.caller_fault(),
            AnalysisError::Eigen(e) => e.caller_fault(),
            AnalysisError::Descriptor(e) => e.caller_fault(),
        }
    }
    /// Stopped by its stop flag (a cancel or a timeout), not failed.
    pub fn is_stop(&self) -> bool {
        matches!(self, AnalysisError::Eigen(spectrum::EigenError::Canceled))
    }
}

impl std::fmt::Display for AnalysisError {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            AnalysisError::InvalidParameter(m) | AnalysisError::InvalidK(m) | AnalysisError::NotApplicable(m) => {
                f.write_str(m)
            }
            AnalysisError::Operator(e) => e.fmt(f),
            AnalysisError::Eigen(e) => e.fmt(f),
            AnalysisError::Descriptor(e) => e.fmt(f),
        }
    }
}

impl From<DescriptorError> for AnalysisError {
    fn from(e: DescriptorError) -> Self {
        AnalysisError::Descriptor(e)
    }
}

impl From<operators::OperatorError> for AnalysisError {
    fn from(e: operators::OperatorError) -> Self {
        AnalysisError::Operator(e)
    }
}

impl From<spectrum::EigenError> for AnalysisError {
    fn from(e: spectrum::EigenError) -> Self {
        AnalysisError::Eigen(e)
    }
}

/// Every name a per-vertex array can have.
pub const ARRAY_NAMES: &[&str] = &[
    "eigenvectors",
    "hks",
    "si_hks",
    "wks",
    "gps",
    "heat_kernel",
    "heat",
    "distance",
    "embedding",
    "fiedler",
    "smoothed",
    "interpolated",
    "labels",
    "scores",
];

/// A per-vertex array in the input numbering, row-major (rows × cols).
#[derive(Debug, Clone, PartialEq)]
pub struct VertexArray {
    pub name: &'static str,
    pub rows: usize,
    pub cols: usize,
    pub data: Vec<f64>,
    /// What the columns are (times, energies, frequencies, …), for JSON and file headers.
    pub columns: Option<Vec<f64>>,
}

impl VertexArray {
    /// Rows as nested JSON arrays (NaN and ±∞ as null).
    pub fn to_json(&self) -> Value {
        Value::Array(
            self.data
                .chunks(self.cols.max(1))
                .map(|r| {
                    Value::Array(
                        r.iter().map(|&v| serde_json::Number::from_f64(v).map_or(Value::Null, Value::Number)).collect(),
                    )
                })
                .collect(),
        )
    }
}

/// The result of an analysis: a JSON summary and per-vertex arrays.
#[derive(Debug, Clone)]
pub struct Output {
    pub summary: Value,
    pub arrays: Vec<VertexArray>,
    /// Shape-DNA fingerprints the analysis computed, for the service's search index.
    pub fingerprints: Vec<Fingerprint>,
}

/// One shape's shape-DNA with the family of parameters it was computed with ([`fingerprint_family`]).
#[derive(Debug, Clone, PartialEq)]
pub struct Fingerprint {
    pub family: String,
    pub shape_id: String,
    pub values: Vec<f64>,
}

/// The family of a fingerprint: every parameter that changes its values (the shape-DNA options and the
/// operator), canonical JSON hashed to 16 hex digits. Fingerprints are compared only within a family.
pub fn fingerprint_family(options: &ShapeDnaOptions, operator: &OperatorSpec) -> String {
    use sha2::Digest;
    let canonical =
        serde_json::to_vec(&json!({ "options": options, "operator": operator, "version": ALGORITHM_VERSION }))
            .unwrap_or_default();
    sha2::Sha256::digest(&canonical).iter().take(8).map(|b| format!("{b:02x}")).collect()
}

/// The cache key of a spectrum: operator and solver parameters (the shape id is the caller's).
pub fn spectrum_key(op: &OperatorSpec, solver: &SolverSpec) -> String {
    // An unverified spectrum must not serve a request that asks for the check.
    serde_json::to_string(&json!({ "operator": op, "solver": solver, "version": ALGORITHM_VERSION }))
        .unwrap_or_default()
}

/// Computed eigenpairs with the operator they belong to.
pub struct Eigen {
    pub operator: Operator,
    pub spectrum: Spectrum,
}

/// Where computed eigenpairs are kept between analyses (the service's cache; the CLI has none). `get` returns
/// an entry with at least `k` pairs for the key, if one exists.
pub trait SpectrumCache: Sync {
    fn get(&self, key: &str, k: usize) -> Option<Arc<Eigen>>;
    fn put(&self, key: &str, eigen: Arc<Eigen>);
}

/// Hooks passed down to the eigensolver.
#[derive(Default, Clone, Copy)]
pub struct Hooks<'a> {
    pub control: Control<'a>,
    pub cache: Option<&'a dyn SpectrumCache>,
    /// Solver threads (0: rayon's pool).
    pub threads: usize,
    /// Told about every eigensolve (for metrics).
    pub on_solve: Option<&'a (dyn Fn(&kac_core::spectrum::Stats) + Sync)>,
}

/// Maps input vertex indices to validated ones.
fn map_vertices(v: &Validated, list: &[u32], what: &str) -> Result<Vec<usize>, AnalysisError> {
    list.iter()
        .map(|&i| match v.vertex_map.get(i as usize) {
            Some(&m) if m != u32::MAX => Ok(m as usize),
            Some(_) => Err(AnalysisError::invalid_parameter(format!("{what}: vertex {i} was dropped by validation"))),
            None => Err(AnalysisError::invalid_parameter(format!(
                "{what}: vertex {i} does not exist ({} vertices)",
                v.vertex_map.len()
            ))),
        })
        .collect()
}

pub fn build_operator(v: &Validated, spec: &OperatorSpec) -> Result<Operator, AnalysisError> {
    let boundary = match (&spec.dirichlet_vertices, spec.boundary) {
        (Some(list), _) => Boundary::DirichletVertices(
            map_vertices(v, list, "dirichlet_vertices")?.iter().map(|&i| i as u32).collect(),
        ),
        (None, BoundarySpec::Dirichlet) => Boundary::Dirichlet,
        (None, BoundarySpec::Neumann) => Boundary::Neumann,
    };
    let o = OperatorOptions {
        operator: spec.operator,
        mass: spec.mass,
        boundary,
        cloud: CloudParams { k: spec.neighbours, neighbourhood: spec.neighbourhood, t: spec.time, radius: None },
        ..Default::default()
    };
    Ok(operators::build(&v.shape, &o)?)
}

/// Zero modes to expect: connected components of the operator for a Neumann problem, none for Dirichlet.
fn expected_zero_modes(op: &Operator) -> usize {
    if op.interior.is_some() {
        0
    } else {
        components(&op.pair).1
    }
}

/// Eigenpairs for an analysis: from the cache when it holds enough, else solved (and cached).
pub fn eigenpairs(
    v: &Validated,
    spec: &OperatorSpec,
    solver: &SolverSpec,
    k: usize,
    hooks: Hooks<'_>,
    reused: &std::cell::Cell<bool>,
) -> Result<Arc<Eigen>, AnalysisError> {
    if k == 0 {
        // Before the cache, which holds at least as many pairs as any k and would answer k = 0 with none.
        return Err(AnalysisError::invalid_k("k = 0: ask for at least one eigenpair (1 ≤ k ≤ the number of unknowns)"));
    }
    let key = format!("{}:{}", v.id.hex(), spectrum_key(spec, solver));
    if let Some(e) = hooks.cache.and_then(|c| c.get(&key, k)) {
        reused.set(true);
        return Ok(e);
    }
    hooks.control.check()?;
    let operator = build_operator(v, spec)?;
    hooks.control.check()?;
    let n = operator.pair.n();
    if k == 0 || k > n {
        return Err(AnalysisError::invalid_k(format!("k = {k} is out of range for {n} unknowns (1 ≤ k ≤ {n})")));
    }
    let opts = EigenOptions { k, tol: solver.tol, threads: hooks.threads, verify: solver.verify, ..Default::default() };
    let spectrum = spectrum::eigs(&operator.pair, &opts, None, hooks.control)?;
    if let Some(f) = hooks.on_solve {
        f(&spectrum.stats);
    }
    let e = Arc::new(Eigen { operator, spectrum });
    if let Some(c) = hooks.cache {
        c.put(&key, e.clone());
    }
    Ok(e)
}

/// A truncated view of cached eigenpairs (the first k).
/// Rows of the eigenvectors per chunk of a per-vertex signature; the stop flag is checked between chunks (a chunk
/// of SI-HKS at k = 500 with 385 τ samples is about 0.3 s of work).
const SIGNATURE_ROWS: usize = 16_384;

/// A per-vertex signature computed chunk by chunk of vertices (each vertex's row depends on its own eigenvector
/// entries and on the eigenvalues only; the grid and every other field come out the same from every chunk), so
/// that a cancel or a timeout takes effect between chunks.
fn by_rows<T>(
    b: &Basis<'_>,
    control: &Control<'_>,
    f: impl Fn(&Basis<'_>) -> Result<T, DescriptorError>,
    values: impl Fn(&mut T) -> &mut faer::Mat<f64>,
) -> Result<T, AnalysisError> {
    let n = b.n();
    if n == 0 {
        return Ok(f(b)?);
    }
    let mut first: Option<T> = None;
    let mut full = faer::Mat::<f64>::zeros(0, 0);
    for r0 in (0..n).step_by(SIGNATURE_ROWS) {
        control.check()?;
        let rows = SIGNATURE_ROWS.min(n - r0);
        let mut part = f(&Basis::new(b.values, b.vectors.subrows(r0, rows), b.zero_tol))?;
        let m = values(&mut part);
        if first.is_none() {
            full = faer::Mat::zeros(n, m.ncols());
        }
        full.as_mut().subrows_mut(r0, rows).copy_from(m.as_ref());
        if first.is_none() {
            first = Some(part);
        }
    }
    let mut out = first.expect("n > 0 rows give a first chunk");
    *values(&mut out) = full;
    Ok(out)
}

fn basis_of(e: &Eigen, k: usize) -> Basis<'_> {
    let k = k.min(e.spectrum.values.len());
    Basis::new(
        &e.spectrum.values[..k],
        e.spectrum.vectors.as_ref().subcols(0, k),
        kac_core::descriptors::zero_threshold(&e.operator.pair),
    )
}

/// Spreads an (operator rows × cols) matrix to the input numbering: Dirichlet vertices 0, dropped ones NaN.
pub fn to_input_rows(v: &Validated, op: &Operator, m: faer::MatRef<'_, f64>, name: &'static str) -> VertexArray {
    spread(v, m, name, |col| op.expand(col))
}

/// Spreads a (validated vertices × cols) matrix to the input numbering.
pub fn validated_to_input(v: &Validated, m: faer::MatRef<'_, f64>, name: &'static str) -> VertexArray {
    spread(v, m, name, |col| col.to_vec())
}

fn spread(
    v: &Validated,
    m: faer::MatRef<'_, f64>,
    name: &'static str,
    expand: impl Fn(&[f64]) -> Vec<f64>,
) -> VertexArray {
    let cols = m.ncols();
    let rows = v.vertex_map.len();
    let mut data = vec![f64::NAN; rows * cols];
    for j in 0..cols {
        let col: Vec<f64> = m.col(j).iter().copied().collect();
        let full = expand(&col);
        for (input, &mapped) in v.vertex_map.iter().enumerate() {
            if mapped != u32::MAX {
                data[input * cols + j] = full[mapped as usize];
            }
        }
    }
    VertexArray { name, rows, cols, data, columns: None }
}

fn operator_json(op: &Operator) -> Value {
    json!({
        "operator": op.kind.name(),
        "mass": op.mass.name(),
        "boundary": op.boundary,
        "size": op.pair.n(),
        "parameters": op.parameters,
    })
}

fn spectrum_json(e: &Eigen, k: usize) -> Value {
    let s = &e.spectrum;
    let k = k.min(s.values.len());
    json!({
        "eigenvalues": &s.values[..k],
        "residuals": &s.residuals[..k.min(s.residuals.len())],
        "solver": {
            "method": s.stats.method, "sigma": s.stats.sigma, "block": s.stats.block, "subspace": s.stats.subspace,
            "restarts": s.stats.restarts, "block_steps": s.stats.block_steps, "solves": s.stats.solves,
            "factor_nonzeros": s.stats.factor_nnz, "factorization": s.stats.factorization,
            "below_sigma": s.stats.below_sigma, "components": s.stats.components, "zero_modes": s.stats.zero_modes,
            "completeness": s.stats.completeness,
        },
        "timings": s.stats.timings,
    })
}

fn merge(mut a: Value, b: Value) -> Value {
    if let (Some(a), Value::Object(b)) = (a.as_object_mut(), b) {
        a.extend(b);
    }
    a
}

pub fn measures(v: &Validated, op: Option<&Operator>) -> Measures {
    let mass_total = op.map(|o| o.pair.mass.iter().sum::<f64>());
    Measures::of(&v.summary(), mass_total)
}

/// The shape-DNA of a shape, typed (for `shape-dna` jobs and comparisons), with the eigenpairs it came from and
/// the number of pairs asked for (k plus the expected zero modes unless they are included).
pub fn shape_dna_of(
    v: &Validated,
    options: &ShapeDnaOptions,
    operator: &OperatorSpec,
    solver: &SolverSpec,
    hooks: Hooks<'_>,
    reused: &std::cell::Cell<bool>,
) -> Result<(Arc<Eigen>, shape_dna::ShapeDna, usize), AnalysisError> {
    let op = build_operator(v, operator)?;
    let zeros = if options.include_zero { 0 } else { expected_zero_modes(&op) };
    let want = (options.k + zeros).min(op.pair.n());
    let e = eigenpairs(v, operator, solver, want, hooks, reused)?;
    let b = basis_of(&e, want);
    let m = measures(v, Some(&e.operator));
    let dna = shape_dna::shape_dna(b.values, b.zero_tol, &m, options)?;
    Ok((e, dna, want))
}

/// Runs an analysis on a validated shape.
pub fn run(v: &Validated, analysis: &Analysis, hooks: Hooks<'_>) -> Result<Output, AnalysisError> {
    let head = json!({ "shape_id": v.id.hex(), "analysis": analysis.name(), "algorithm_version": ALGORITHM_VERSION });
    // Whether the eigenpairs came from the cache (no eigensolve for this analysis).
    let reused = std::cell::Cell::new(false);
    let out = match analysis {
        Analysis::Spectrum { k, eigenvectors, operator, solver } => {
            let e = eigenpairs(v, operator, solver, *k, hooks, &reused)?;
            let mut arrays = vec![];
            if *eigenvectors {
                let k = (*k).min(e.spectrum.values.len());
                let mut a = to_input_rows(v, &e.operator, e.spectrum.vectors.as_ref().subcols(0, k), "eigenvectors");
                a.columns = Some(e.spectrum.values[..k].to_vec());
                arrays.push(a);
            }
            let summary = merge(
                merge(
                    json!({ "k": k, "residual_norm": "‖Lφ − λMφ‖₂ / (max(|λ|, |σ|)·‖Mφ‖₂)", "sign_convention": signatures::SIGN_CONVENTION }),
                    operator_json(&e.operator),
                ),
                spectrum_json(&e, *k),
            );
            // Also at the top level, where results before the check was on by default carried it.
            let mut summary = summary;
            summary["completeness"] = json!(e.spectrum.stats.completeness);
            Output { fingerprints: vec![], summary, arrays }
        }
        Analysis::Hks { k, options, operator, solver } => {
            let e = eigenpairs(v, operator, solver, *k, hooks, &reused)?;
            hooks.control.phase("descriptor", 0, 0)?;
            let h = by_rows(&basis_of(&e, *k), &hooks.control, |b| signatures::hks(b, options), |h| &mut h.values)?;
            let summary = json!({ "k": k, "hks": h, "options": options });
            signature(v, &e, h.values.as_ref(), "hks", h.times.clone(), summary)
        }
        Analysis::SiHks { k, options, operator, solver } => {
            let e = eigenpairs(v, operator, solver, *k, hooks, &reused)?;
            hooks.control.phase("descriptor", 0, 0)?;
            let h = by_rows(&basis_of(&e, *k), &hooks.control, |b| signatures::si_hks(b, options), |h| &mut h.values)?;
            let columns = h.frequencies.iter().map(|&f| f as f64).collect();
            let summary = json!({ "k": k, "si_hks": h, "options": options });
            signature(v, &e, h.values.as_ref(), "si_hks", columns, summary)
        }
        Analysis::Wks { k, options, operator, solver } => {
            let e = eigenpairs(v, operator, solver, *k, hooks, &reused)?;
            hooks.control.phase("descriptor", 0, 0)?;
            let w = by_rows(&basis_of(&e, *k), &hooks.control, |b| signatures::wks(b, options), |w| &mut w.values)?;
            let summary = json!({ "k": k, "wks": w, "options": options });
            signature(v, &e, w.values.as_ref(), "wks", w.energies.clone(), summary)
        }
        Analysis::Gps { k, dimensions, operator, solver } => {
            let e = eigenpairs(v, operator, solver, *k, hooks, &reused)?;
            // Not by rows: each eigenvector's sign is fixed by its largest entry over all vertices.
            hooks.control.phase("descriptor", 0, 0)?;
            let g = signatures::gps(&basis_of(&e, *k), *dimensions)?;
            let summary = json!({ "k": k, "gps": g });
            signature(v, &e, g.values.as_ref(), "gps", g.eigenvalues.clone(), summary)
        }
        Analysis::ShapeDna { options, operator, solver } => {
            let (e, dna, want) = shape_dna_of(v, options, operator, solver, hooks, &reused)?;
            let b = basis_of(&e, want);
            let m = measures(v, Some(&e.operator));
            let weyl = weyl_estimate(b.values, b.zero_tol, &m).ok();
            let summary = merge(
                json!({ "shape_dna": dna, "weyl": weyl, "measures": m, "options": options, "residuals": &e.spectrum.residuals[..want.min(e.spectrum.residuals.len())] }),
                operator_json(&e.operator),
            );
            let family = fingerprint_family(options, operator);
            let fingerprints = vec![Fingerprint { family, shape_id: v.id.hex(), values: dna.values.clone() }];
            Output { fingerprints, summary, arrays: vec![] }
        }
        Analysis::Heat { k, times, sources, method, steps, operator, solver } => {
            let src = map_vertices(v, sources, "sources")?;
            match method {
                HeatMethod::Spectral => {
                    let e = eigenpairs(v, operator, solver, *k, hooks, &reused)?;
                    let b = basis_of(&e, *k);
                    let times = match times {
                        Some(t) => t.clone(),
                        None => signatures::default_hks_times(&b, 10)?,
                    };
                    kac_core::descriptors::check_times("times", &times)?;
                    let trace = heat_trace(b.values, &times);
                    let tail: Vec<f64> = times.iter().map(|&t| heat_trace_tail_bound(b.values, b.n(), t)).collect();
                    let mut arrays = vec![];
                    let src_op = to_operator_rows(&e.operator, &src)?;
                    let mut rows_json = vec![];
                    for (s_in, &s) in sources.iter().zip(&src_op) {
                        hooks.control.check()?;
                        // k_t(s, ·) for every t, and what truncation can miss of the flow of the hat function at s.
                        let kt = heat_kernel_row(&b, s, &times)?;
                        let mut u0 = vec![0.0; b.n()];
                        u0[s] = 1.0;
                        let d = diffuse_spectral(&b, &e.operator.pair, &u0, &times)?;
                        rows_json.push(json!({ "source": s_in, "hat_function_truncation_bound": d.truncation_bound }));
                        let mut a = to_input_rows(v, &e.operator, kt.as_ref(), "heat_kernel");
                        a.columns = Some(times.clone());
                        arrays.push(a);
                    }
                    // Dirichlet problems also lose heat through the boundary: Q(t) = ∫ u(t) from u₀ = 1.
                    let content = match e.operator.interior {
                        Some(_) => Some(kac_core::descriptors::heat::heat_content(&b, &e.operator.pair, &times)?),
                        None => None,
                    };
                    let summary = merge(
                        json!({ "method": "spectral", "k": k, "times": times, "heat_content": content, "heat_trace": trace, "heat_trace_tail_bound": tail, "sources": rows_json, "arrays": "one per source: the heat kernel k_t(source, ·), a column per time" }),
                        operator_json(&e.operator),
                    );
                    Output { fingerprints: vec![], summary, arrays }
                }
                HeatMethod::Implicit => {
                    let op = build_operator(v, operator)?;
                    let times = times
                        .clone()
                        .ok_or_else(|| AnalysisError::invalid_parameter("the implicit method needs times"))?;
                    let src_op = to_operator_rows(&op, &src)?;
                    let mut arrays = vec![];
                    for &s in &src_op {
                        hooks.control.check()?;
                        let mut u0 = vec![0.0; op.pair.n()];
                        u0[s] = 1.0;
                        let u = pde::heat_implicit(&op.pair, &u0, &times, *steps)?;
                        let mut a = to_input_rows(v, &op, u.as_ref(), "heat");
                        a.columns = Some(times.clone());
                        arrays.push(a);
                    }
                    let summary = merge(
                        json!({ "method": "implicit", "steps": steps, "times": times, "sources": sources, "arrays": "one per source: backward-Euler flow of u₀ = the hat function at the source, a column per time" }),
                        operator_json(&op),
                    );
                    Output { fingerprints: vec![], summary, arrays }
                }
            }
        }
        Analysis::Geodesic { sources, options } => {
            let Shape::TriangleMesh(mesh) = &v.shape else {
                return Err(AnalysisError::not_applicable(format!(
                    "geodesics by the heat method need a triangle mesh, not a {}",
                    v.shape.kind().as_str()
                )));
            };
            let src = map_vertices(v, sources, "sources")?;
            let g = geodesic::heat_method(mesh, &src, options)?;
            let n = mesh.vertices.len();
            let mut m = faer::Mat::<f64>::zeros(n, 1 + usize::from(g.varadhan.is_some()));
            for i in 0..n {
                m[(i, 0)] = g.distance[i];
                if let Some(va) = &g.varadhan {
                    m[(i, 1)] = va[i];
                }
            }
            let a = validated_to_input(v, m.as_ref(), "distance");
            let finite: Vec<f64> = g.distance.iter().copied().filter(|d| d.is_finite()).collect();
            let max = finite.iter().copied().fold(0.0, f64::max);
            let summary = json!({
                "geodesic": g, "options": options, "max_distance": max,
                "columns": if g.varadhan.is_some() { vec!["heat_method", "varadhan"] } else { vec!["heat_method"] },
                "operator": "cotan", "mass": "lumped",
            });
            Output { fingerprints: vec![], summary, arrays: vec![a] }
        }
        Analysis::Trees {} => {
            let (edges, weights) = operators::edge_graph(&v.shape)
                .ok_or_else(|| AnalysisError::not_applicable("a point cloud has no edges; build a graph first"))?;
            let t = spanning_trees(v.shape.vertex_count(), &edges, &weights)?;
            Output { fingerprints: vec![], summary: json!({ "trees": t }), arrays: vec![] }
        }
        Analysis::Embed { dimensions, scaling, operator, solver } => {
            let op = build_operator(v, operator)?;
            let zeros = expected_zero_modes(&op);
            let want = (dimensions + zeros).min(op.pair.n());
            let e = eigenpairs(v, operator, solver, want, hooks, &reused)?;
            let b = basis_of(&e, want);
            let (coords, vals) = eigenmap(&b, *dimensions, *scaling == EmbedScaling::Gps)?;
            let f = fiedler(&b, &e.operator.pair, false).ok();
            let mut a = to_input_rows(v, &e.operator, coords.as_ref(), "embedding");
            a.columns = Some(vals.clone());
            let mut arrays = vec![a];
            if let Some(f) = &f {
                let fm = faer::Mat::from_fn(f.vector.len(), 1, |i, _| f.vector[i]);
                arrays.push(to_input_rows(v, &e.operator, fm.as_ref(), "fiedler"));
            }
            let summary = merge(
                json!({ "dimensions": dimensions, "scaling": scaling, "eigenvalues": vals, "fiedler": f, "components": components(&e.operator.pair).1, "sign_convention": signatures::SIGN_CONVENTION }),
                operator_json(&e.operator),
            );
            Output { fingerprints: vec![], summary, arrays }
        }
        Analysis::Smooth { alpha, function, fixed_boundary, operator } => {
            let op = build_operator(v, operator)?;
            let n = op.pair.n();
            if op.interior.is_some() {
                return Err(AnalysisError::invalid_parameter(
                    "smoothing takes a Neumann operator; use fixed_boundary to clamp",
                ));
            }
            let (ubar, what) = match function {
                Some(f) => {
                    let mapped = from_input_rows(v, f, "function")?;
                    (faer::Mat::from_fn(n, 1, |i, _| mapped[i]), "function")
                }
                None => {
                    let pos = v.shape.positions().ok_or_else(|| {
                        AnalysisError::not_applicable("the shape has no coordinates; give a function")
                    })?;
                    (faer::Mat::from_fn(n, 3, |i, j| pos[i][j]), "coordinates")
                }
            };
            let fixed = fixed_boundary.then(|| operators::boundary::boundary_vertices(&v.shape));
            let u = pde::smooth(&op.pair, ubar.as_ref(), *alpha, fixed.as_deref())?;
            let a = to_input_rows(v, &op, u.as_ref(), "smoothed");
            let summary = merge(
                json!({ "alpha": alpha, "smoothed": what, "fixed_boundary": fixed_boundary, "equation": "(M + αL) u = M ū" }),
                operator_json(&op),
            );
            Output { fingerprints: vec![], summary, arrays: vec![a] }
        }
        Analysis::Interpolate { values, labels, operator } => {
            let op = build_operator(v, operator)?;
            if op.interior.is_some() {
                return Err(AnalysisError::invalid_parameter(
                    "interpolation fixes its own vertices; use a Neumann operator",
                ));
            }
            match (values.is_empty(), labels.is_empty()) {
                (false, true) => {
                    let idx = map_vertices(v, &values.iter().map(|x| x.0).collect::<Vec<_>>(), "values")?;
                    let known: Vec<(usize, f64)> = idx.into_iter().zip(values.iter().map(|x| x.1)).collect();
                    let u = pde::harmonic(&op.pair, &known)?;
                    let um = faer::Mat::from_fn(u.len(), 1, |i, _| u[i]);
                    let a = to_input_rows(v, &op, um.as_ref(), "interpolated");
                    Output {
                        fingerprints: vec![],
                        summary: merge(json!({ "known": values.len(), "method": "harmonic" }), operator_json(&op)),
                        arrays: vec![a],
                    }
                }
                (true, false) => {
                    let idx = map_vertices(v, &labels.iter().map(|x| x.0).collect::<Vec<_>>(), "labels")?;
                    let l: Vec<(usize, u32)> = idx.into_iter().zip(labels.iter().map(|x| x.1)).collect();
                    let r = pde::labels(&op.pair, &l)?;
                    let lm = faer::Mat::from_fn(r.label.len(), 1, |i, _| r.label[i] as f64);
                    let mut a = to_input_rows(v, &op, lm.as_ref(), "labels");
                    a.columns = None;
                    let mut s = to_input_rows(v, &op, r.scores.as_ref(), "scores");
                    s.columns = Some(r.classes.iter().map(|&c| c as f64).collect());
                    Output {
                        fingerprints: vec![],
                        summary: merge(
                            json!({ "labels": r, "method": "harmonic (Zhu et al. 2003)" }),
                            operator_json(&op),
                        ),
                        arrays: vec![a, s],
                    }
                }
                _ => {
                    return Err(AnalysisError::invalid_parameter(
                        "give either values or labels (not both, not neither)",
                    ))
                }
            }
        }
    };
    let mut summary = merge(head, out.summary);
    if let Some(o) = summary.as_object_mut() {
        o.insert("eigenpairs_reused".into(), reused.get().into());
    }
    Ok(Output { fingerprints: out.fingerprints, summary, arrays: out.arrays })
}

/// The output of a per-vertex signature: its summary with the operator's, and its values as one array.
fn signature(
    v: &Validated,
    e: &Eigen,
    values: faer::MatRef<'_, f64>,
    name: &'static str,
    columns: Vec<f64>,
    summary: Value,
) -> Output {
    let mut a = to_input_rows(v, &e.operator, values, name);
    a.columns = Some(columns);
    Output { fingerprints: vec![], summary: merge(summary, operator_json(&e.operator)), arrays: vec![a] }
}

/// Validated vertex indices → rows of the (possibly Dirichlet-condensed) operator.
fn to_operator_rows(op: &Operator, list: &[usize]) -> Result<Vec<usize>, AnalysisError> {
    match &op.interior {
        None => Ok(list.to_vec()),
        Some(keep) => list
            .iter()
            .map(|&i| {
                keep.binary_search(&(i as u32))
                    .map_err(|_| AnalysisError::invalid_parameter(format!("vertex {i} is on the Dirichlet boundary")))
            })
            .collect(),
    }
}

/// A per-vertex function in the input numbering → the validated numbering (welded vertices: the first value).
fn from_input_rows(v: &Validated, f: &[f64], what: &str) -> Result<Vec<f64>, AnalysisError> {
    if f.len() != v.vertex_map.len() {
        return Err(AnalysisError::invalid_parameter(format!(
            "{what}: {} values for {} input vertices",
            f.len(),
            v.vertex_map.len()
        )));
    }
    let mut out = vec![f64::NAN; v.shape.vertex_count()];
    for (i, &m) in v.vertex_map.iter().enumerate() {
        if m != u32::MAX && out[m as usize].is_nan() {
            out[m as usize] = f[i];
        }
    }
    if let Some(i) = out.iter().position(|x| !x.is_finite()) {
        return Err(AnalysisError::invalid_parameter(format!("{what}: vertex {i} has no finite value")));
    }
    Ok(out)
}

kac_core::object_only_serde!(OperatorSpec);

kac_core::object_only_serde!(SolverSpec);

#[cfg(test)]
mod tests {
    use super::*;

    /// Signatures computed by chunks of vertices equal the signature of the whole basis, and a raised stop flag
    /// ends the computation between chunks.
    #[test]
    fn signatures_by_rows_equal_the_whole_and_stop_between_chunks() {
        let shape = Shape::TriangleMesh(kac_core::geometry::generate::icosphere(6));
        let op = operators::build(&shape, &OperatorOptions::default()).unwrap();
        assert!(op.pair.n() > 2 * SIGNATURE_ROWS);
        let s =
            spectrum::eigs(&op.pair, &EigenOptions { k: 20, ..Default::default() }, None, Control::default()).unwrap();
        let b = Basis::new(&s.values, s.vectors.as_ref(), kac_core::descriptors::zero_threshold(&op.pair));
        let go = Control::default();
        // Equal to rounding (a product's kernel may differ for a chunk's remainder rows on some CPUs).
        let close = |a: &faer::Mat<f64>, b: &faer::Mat<f64>| {
            assert_eq!((a.nrows(), a.ncols()), (b.nrows(), b.ncols()));
            let scale = (0..b.ncols())
                .flat_map(|j| (0..b.nrows()).map(move |i| (i, j)))
                .fold(0.0f64, |m, (i, j)| m.max(b[(i, j)].abs()));
            for j in 0..a.ncols() {
                for i in 0..a.nrows() {
                    assert!(
                        (a[(i, j)] - b[(i, j)]).abs() <= 1e-12 * scale,
                        "({i}, {j}): {} vs {}",
                        a[(i, j)],
                        b[(i, j)]
                    );
                }
            }
        };
        let h = by_rows(&b, &go, |b| signatures::hks(b, &HksOptions::default()), |h| &mut h.values).unwrap();
        let whole = signatures::hks(&b, &HksOptions::default()).unwrap();
        assert_eq!((h.times.clone(), h.values.nrows()), (whole.times.clone(), whole.values.nrows()));
        close(&h.values, &whole.values);
        let si = by_rows(&b, &go, |b| signatures::si_hks(b, &SiHksOptions::default()), |h| &mut h.values).unwrap();
        close(&si.values, &signatures::si_hks(&b, &SiHksOptions::default()).unwrap().values);
        let w = by_rows(&b, &go, |b| signatures::wks(b, &WksOptions::default()), |w| &mut w.values).unwrap();
        close(&w.values, &signatures::wks(&b, &WksOptions::default()).unwrap().values);
        let stop = std::sync::atomic::AtomicBool::new(true);
        let stopped = Control { progress: None, stop: Some(&stop) };
        let r = by_rows(&b, &stopped, |b| signatures::hks(b, &HksOptions::default()), |h| &mut h.values);
        assert_eq!(r.err().map(|e| e.code()), Some("canceled"));
    }
}
