//! The analysis requests: what a client can ask of a stored shape, one serde type shared by the CLI and the
//! service (each analysis with its parameters and defaults), and beside each what follows from it alone: the
//! eigenpairs it asks for, what it holds (the service's limits), the inputs it takes (checked against the shape),
//! and its entry in the registry (where it is valid). With its core call (`dispatch.rs`) and its result type
//! (`results.rs`), that is all an analysis is written as; see docs/layout.md.

use super::inputs::{check_initial, check_pairs, check_per_vertex, check_value, check_vertices, elements};

use super::*;

/// Bumped whenever an analysis' numbers could change for the same request (part of job ids).
pub const ALGORITHM_VERSION: u32 = 10;

/// Bumped whenever a fingerprint's values could change for the same shape-DNA options and operator (part of the
/// fingerprint family, so that stored fingerprints stay comparable across versions that change other numbers
/// only). Version 10 of the analyses changed Weyl estimates, heat curvature's window and result fields, not
/// shape-DNA's values.
pub const FINGERPRINT_VERSION: u32 = 9;

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
    /// The retrieval fingerprint: shape-DNA, the heat distribution and the GPS D2 distribution from one
    /// eigensolve, each kept in the search index as a family of its own (`POST /v1/search`).
    Fingerprint {
        #[serde(default)]
        options: FingerprintOptions,
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
            Analysis::Fingerprint { .. } => "fingerprint",
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
            | Analysis::Fingerprint { operator, .. }
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
            | Analysis::Fingerprint { solver, .. }
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

impl Analysis {
    /// The eigenpairs an analysis asks for, by the name of the field that asks (no default arm: a new analysis must
    /// say whether it asks for any).
    pub fn asked(&self) -> Option<(&'static str, usize)> {
        match self {
            Analysis::Spectrum { k, .. }
            | Analysis::Hks { k, .. }
            | Analysis::SiHks { k, .. }
            | Analysis::Wks { k, .. }
            | Analysis::Gps { k, .. }
            | Analysis::Heat { k, .. }
            | Analysis::HeatCurvature { k, .. }
            | Analysis::Wave { k, .. }
            | Analysis::Schrodinger { k, .. } => Some(("k", *k)),
            Analysis::Diffuse { k, method, .. } => (*method == HeatMethod::Spectral).then_some(("k", *k)),
            Analysis::ShapeDna { options, .. } => Some(("options.k", options.k)),
            Analysis::Fingerprint { options, .. } => Some(("options.k", options.k)),
            Analysis::Embed { dimensions, .. } => Some(("dimensions", *dimensions)),
            Analysis::Operator { .. }
            | Analysis::Gradient { .. }
            | Analysis::Divergence { .. }
            | Analysis::Geodesic { .. }
            | Analysis::Trees { .. }
            | Analysis::MeanCurvature { .. }
            | Analysis::Poisson { .. }
            | Analysis::DirichletEnergy { .. }
            | Analysis::Smooth { .. }
            | Analysis::Interpolate { .. } => None,
        }
    }

    /// What the request asks to hold: every list or grid, by the name of its field (checked against
    /// --max-samples), and the columns of the widest per-vertex array the analysis holds, eigenvectors included
    /// (against --max-output-values). No default arm: a new analysis must say what it holds.
    pub fn demand(&self) -> (Vec<(&'static str, usize)>, usize) {
        let len = |v: &Option<Vec<f64>>| v.as_ref().map(Vec::len);
        match self {
            // The k eigenvectors are held (and cached) whether or not they are returned.
            Analysis::Spectrum { k, .. } => (vec![], *k),
            // The matrices' non-zeros are counted against --max-output-values once assembled (by the runner).
            Analysis::Operator { .. } => (vec![], 1),
            Analysis::Hks { k, options, .. } => {
                let t = len(&options.times).unwrap_or(options.count);
                (vec![("options.count", options.count), ("options.times", t)], t.max(*k))
            }
            Analysis::SiHks { k, options, .. } => (
                vec![("options.samples", options.samples), ("options.frequencies", options.frequencies)],
                options.samples.max(options.frequencies).max(*k),
            ),
            Analysis::Wks { k, options, .. } => {
                let e = len(&options.energies).unwrap_or(options.count);
                (vec![("options.count", options.count), ("options.energies", e)], e.max(*k))
            }
            Analysis::Gps { k, dimensions, .. } => (vec![], dimensions.unwrap_or(*k).max(*k)),
            Analysis::ShapeDna { options, .. } => (vec![], options.k),
            // The k eigenvectors, and GPS's sampled points' pairwise distances (about 80,000, transient).
            Analysis::Fingerprint { options, .. } => (vec![], options.k),
            Analysis::Heat { k, times, sources, steps, .. } => {
                let t = len(times).unwrap_or(10);
                (
                    vec![("times", t), ("sources", sources.len()), ("steps", *steps)],
                    t.saturating_mul(sources.len().max(1)).max(*k),
                )
            }
            Analysis::Geodesic { sources, options } => {
                (vec![("sources", sources.len()), ("options.varadhan_steps", options.varadhan_steps)], 2)
            }
            Analysis::Trees {} => (vec![], 1),
            // Per-element arrays: as many rows as elements, about 2 (triangles) to 6 (tets) per vertex.
            Analysis::Gradient { function } => (vec![("function", function.len())], 3 * 6),
            Analysis::Divergence { field, .. } => (vec![("field", field.len())], 2),
            Analysis::MeanCurvature {} => (vec![], 3),
            Analysis::Poisson { g, dirichlet_values, .. } => {
                (vec![("g", g.len()), ("dirichlet_values", dirichlet_values.as_ref().map_or(0, Vec::len))], 1)
            }
            Analysis::Diffuse { k, times, steps, method, .. } => {
                let k = if *method == HeatMethod::Spectral { *k } else { 0 };
                (vec![("times", times.len()), ("steps", *steps)], times.len().max(k))
            }
            Analysis::DirichletEnergy { function, .. } => {
                (vec![("function", function.as_ref().map_or(0, Vec::len))], 3)
            }
            Analysis::Wave { k, times, .. } => (vec![("times", times.len())], times.len().max(*k)),
            // Real and imaginary parts: twice the times.
            Analysis::Schrodinger { k, times, .. } => {
                (vec![("times", times.len())], times.len().saturating_mul(2).max(*k))
            }
            Analysis::HeatCurvature { k, times, .. } => (vec![("times", len(times).unwrap_or(8))], *k),
            Analysis::Embed { dimensions, .. } => (vec![], dimensions.saturating_add(1)),
            Analysis::Smooth { .. } => (vec![], 3),
            Analysis::Interpolate { values, labels, .. } => {
                let classes = labels.iter().map(|l| l.1 as usize + 1).max().unwrap_or(1);
                (vec![("values", values.len()), ("labels", labels.len()), ("classes in labels", classes)], classes)
            }
        }
    }

    /// Every per-vertex and per-element array and every vertex index of the request, against the shape it is for
    /// (see the module's documentation). No default arm: a new analysis must say what it takes.
    pub fn check_inputs(&self, v: &Validated) -> Result<(), AnalysisError> {
        if let Some(list) = self.operator_spec().and_then(|o| o.dirichlet_vertices.as_ref()) {
            check_vertices(v, "operator.dirichlet_vertices", list)?;
        }
        match self {
            Analysis::Heat { sources, .. } | Analysis::Geodesic { sources, .. } => {
                check_vertices(v, "sources", sources)
            }
            Analysis::Wave { start, velocity, .. } => {
                check_initial(v, start)?;
                velocity.as_ref().map_or(Ok(()), |f| check_per_vertex(v, "velocity", f))
            }
            Analysis::Schrodinger { start, initial_imag, .. } => {
                check_initial(v, start)?;
                initial_imag.as_ref().map_or(Ok(()), |f| check_per_vertex(v, "initial_imag", f))
            }
            Analysis::Diffuse { start, .. } => check_initial(v, start),
            Analysis::Poisson { g, dirichlet_values, .. } => {
                check_per_vertex(v, "g", g)?;
                dirichlet_values.as_ref().map_or(Ok(()), |d| check_pairs(v, "dirichlet_values", d, true))
            }
            Analysis::DirichletEnergy { function, .. } | Analysis::Smooth { function, .. } => {
                function.as_ref().map_or(Ok(()), |f| check_per_vertex(v, "function", f))
            }
            Analysis::Gradient { function } => check_per_vertex(v, "function", function),
            Analysis::Divergence { field, .. } => {
                if let Some(n) = elements(&v.shape) {
                    if field.len() != n {
                        return Err(AnalysisError::invalid_parameter(format!(
                            "field: {} vectors for {n} elements (one per triangle or tetrahedron, in the validated \
                             mesh's order)",
                            field.len()
                        )));
                    }
                }
                field.iter().enumerate().try_for_each(|(e, x)| {
                    x.iter().enumerate().try_for_each(|(c, &y)| check_value("field", &format!("element {e}[{c}]"), y))
                })
            }
            Analysis::Interpolate { values, labels, .. } => {
                check_pairs(v, "values", values, true)?;
                let as_values: Vec<(u32, f64)> = labels.iter().map(|&(i, c)| (i, f64::from(c))).collect();
                check_pairs(v, "labels", &as_values, false)
            }
            Analysis::Spectrum { .. }
            | Analysis::Operator { .. }
            | Analysis::Hks { .. }
            | Analysis::SiHks { .. }
            | Analysis::Wks { .. }
            | Analysis::Gps { .. }
            | Analysis::ShapeDna { .. }
            | Analysis::Fingerprint { .. }
            | Analysis::Trees { .. }
            | Analysis::MeanCurvature { .. }
            | Analysis::HeatCurvature { .. }
            | Analysis::Embed { .. } => Ok(()),
        }
    }
}
