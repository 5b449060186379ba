//! Correspondence between two shapes (`kac correspondence`): each shape's eigenpairs (the cache's where it has
//! them), the functional map and its ZoomOut refinement ([`kac_core::correspondence`]), and the vertex maps both
//! ways in the uploads' numbering.

use super::*;
use kac_core::correspondence::{self as fm, CorrespondenceError, CorrespondenceOptions, SpectralShape};

/// What a correspondence returns besides its arrays (`source_to_target`, `target_to_source` and their costs).
#[derive(Debug, Clone, Serialize, utoipa::ToSchema)]
pub struct CorrespondenceSummary {
    pub source_id: String,
    pub target_id: String,
    pub options: CorrespondenceOptions,
    /// The target's basis size at the fit and at each refinement step.
    pub sizes: Vec<usize>,
    /// C (k_T × k_S), rows of coefficients: the final functional map from the source's eigenfunctions to the
    /// target's.
    pub functional_map: Vec<Vec<f64>>,
    /// ‖CCᵀ − I‖_F / √k_T: near 0 for a near-isometry or a part; large where the map is not one.
    pub orthogonality_defect: f64,
    /// The matches' distances in the spectral embedding (small: confident).
    pub source_cost: FiniteStats,
    pub target_cost: FiniteStats,
    /// Eigenpairs computed per shape.
    pub eigenpairs: usize,
    /// The source's operator (the target's is built with the same options).
    #[serde(flatten)]
    pub operator: OperatorUsed,
    /// What the arrays are.
    pub maps: &'static str,
}

impl From<CorrespondenceError> for AnalysisError {
    fn from(e: CorrespondenceError) -> Self {
        match e {
            CorrespondenceError::Descriptor(d) => d.into(),
            CorrespondenceError::Stopped(s) => s.into(),
        }
    }
}

/// A per-vertex array of the source carried to the target: `labels` by the vertex map (each target vertex takes
/// its match's value), a function by the functional map (its band-limited part).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, utoipa::ToSchema)]
pub struct Transfer {
    /// One value per source vertex (the upload's numbering).
    pub values: Vec<f64>,
    /// Labels (class ids) rather than a function.
    #[serde(default)]
    pub labels: bool,
}

/// For each validated vertex, the first input vertex welded into it.
fn first_input(v: &Validated) -> Vec<u32> {
    let mut first = vec![u32::MAX; v.shape.vertex_count()];
    for (input, &w) in v.vertex_map.iter().enumerate() {
        if w != u32::MAX && first[w as usize] == u32::MAX {
            first[w as usize] = input as u32;
        }
    }
    first
}

/// The orthogonality defect of C above which a correspondence carries the warning `correspondence-not-isometric`.
/// Measured (kac_core::correspondence's tests): below 0.05 for isometries (shuffled rigid copies, bends), 0.22 for
/// the exact map of a copy with a cap cut off (C of a part is rectangular, its rows orthonormal only on the part's
/// spectrum), 0.47 for the wrong map of that copy without landmarks (mean geodesic error 0.38).
pub const MAP_DEFECT_WARN: f64 = 0.35;

/// The correspondence from `source` to `target` under one operator spec (Neumann, order 1: the maps are between
/// vertices), with `options.refine_k` eigenpairs per shape, as a result of its own (`analysis: correspondence`,
/// the source its shape): one builder for the CLI and the service.
pub fn correspondence(
    source: &Validated,
    target: &Validated,
    options: &CorrespondenceOptions,
    operator: &OperatorSpec,
    solver: &SolverSpec,
    transfer: Option<&Transfer>,
    hooks: Hooks<'_>,
) -> Result<Output, AnalysisError> {
    // The options, the operator, the shapes' kinds, the landmarks and the array to transfer, before any solve.
    check_correspondence(source, target, options, operator, transfer)?;
    let carried = match transfer {
        Some(t) => Some(from_input_rows(source, &t.values, "transfer.values")?),
        None => None,
    };
    // Landmarks in the uploads' numbering, to the validated one.
    let (ls, lt): (Vec<u32>, Vec<u32>) = options.landmarks.iter().copied().unzip();
    let ls = map_vertices(source, &ls, "landmarks (source)")?;
    let lt = map_vertices(target, &lt, "landmarks (target)")?;
    let mut core = options.clone();
    core.landmarks = ls.iter().zip(&lt).map(|(&a, &b)| (a as u32, b as u32)).collect();
    // The maps are between vertices: an operator over fewer unknowns (a point cloud whose outliers it leaves out)
    // has no row for some of them. Refused before any eigensolve.
    for (v, which) in [(source, "source"), (target, "target")] {
        let dropped = kac_core::operators::dropped_points(&v.shape, &operator_options(v, operator)?)?;
        if let Some(&first) = dropped.first() {
            return Err(AnalysisError::not_applicable(format!(
                "the {which}'s operator leaves {} points out as outliers (the first: validated point {first}): a \
                 correspondence maps every vertex; clean the cloud first, or set denoise to false",
                dropped.len()
            )));
        }
    }
    let k = options.refine_k.max(options.fit_k);
    // A partial target's basis corresponds to more of the full source's eigenfunctions (their count follows the
    // areas): the source gets up to twice as many.
    let k_source = if options.partial { 2 * k } else { k };
    // Both spectra side by side, each on half the threads: a solve of this size gains little from a second thread,
    // two solves nearly twice (BENCHMARKS.md, "Why the code is as it is"). A side that fails does not stop the
    // other: its error comes when both are done.
    let total = if hooks.threads == 0 { rayon::current_num_threads() } else { hooks.threads };
    let solve = |v: &Validated, k: usize, threads: usize| {
        let reused = std::cell::Cell::new(false);
        let e = eigenpairs(v, operator, solver, k.min(v.shape.vertex_count()), Hooks { threads, ..hooks }, &reused)?;
        Ok::<_, AnalysisError>((e, reused.get()))
    };
    let ((es, source_reused), (et, target_reused)) = if source.id == target.id && k_source == k {
        // One shape against itself: one solve serves both sides.
        let one = solve(source, k, total)?;
        (one.clone(), one)
    } else if total >= 2 {
        let (a, b) = rayon::join(|| solve(source, k_source, total / 2), || solve(target, k, total - total / 2));
        (a?, b?)
    } else {
        let a = solve(source, k_source, total)?;
        hooks.control.check()?;
        (a, solve(target, k, total)?)
    };
    let reused = source_reused || target_reused;
    hooks.control.phase("correspondence", 0, 0)?;
    // Checked above for what the operator drops; this holds for whatever else would (defensive: a map past an
    // operator's rows would index out of bounds).
    for (e, which) in [(&es, "source"), (&et, "target")] {
        if e.operator.interior.is_some() || e.operator.pair.n() != e.operator.full_size {
            return Err(AnalysisError::not_applicable(format!(
                "the {which}'s operator leaves vertices out (a cloud's outliers): a correspondence maps every \
                 vertex; clean the cloud first"
            )));
        }
    }
    // The surfaces orient the orientation term (triangle meshes; vertices are the operator's unknowns here).
    fn surface(v: &Validated) -> Option<&kac_core::geometry::TriangleMesh> {
        match &v.shape {
            kac_core::Shape::TriangleMesh(m) => Some(m),
            _ => None,
        }
    }
    let s = SpectralShape { basis: basis_of(&es, k_source), pair: &es.operator.pair, surface: surface(source) };
    let t = SpectralShape { basis: basis_of(&et, k), pair: &et.operator.pair, surface: surface(target) };
    let r = fm::correspond(&s, &t, &core, &hooks.control)?;
    // The maps in the uploads' numbering: row i of `source_to_target` is input vertex i of the source, its value
    // the input vertex of the target it matches (NaN for a vertex validation dropped).
    let (fs, ft) = (first_input(source), first_input(target));
    let to_input = |v: &Validated, map: &[u32], other: &[u32]| -> Vec<f64> {
        v.vertex_map
            .iter()
            .map(|&w| if w == u32::MAX { f64::NAN } else { f64::from(other[map[w as usize] as usize]) })
            .collect()
    };
    let column = |v: &Validated, values: &[f64]| -> Vec<f64> {
        v.vertex_map.iter().map(|&w| if w == u32::MAX { f64::NAN } else { values[w as usize] }).collect()
    };
    let array = |name: &'static str, v: &Validated, data: Vec<f64>| VertexArray {
        name,
        rows: v.vertex_map.len(),
        cols: 1,
        data,
        columns: None,
    };
    let mut arrays = vec![
        array("source_to_target", source, to_input(source, &r.source_to_target, &ft)),
        array("target_to_source", target, to_input(target, &r.target_to_source, &fs)),
        array("source_cost", source, column(source, &r.source_cost)),
        array("target_cost", target, column(target, &r.target_cost)),
    ];
    if let (Some(f), Some(how)) = (&carried, transfer) {
        let on_target: Vec<f64> = match how.labels {
            true => r.target_to_source.iter().map(|&x| f[x as usize]).collect(),
            false => fm::transfer_function(&s, &t, &r.c, f),
        };
        arrays.push(array("transferred", target, column(target, &on_target)));
    }
    let summary = CorrespondenceSummary {
        source_id: source.id.hex(),
        target_id: target.id.hex(),
        options: options.clone(),
        sizes: r.sizes.clone(),
        functional_map: (0..r.c.nrows()).map(|i| (0..r.c.ncols()).map(|j| r.c[(i, j)]).collect()).collect(),
        orthogonality_defect: r.orthogonality_defect,
        source_cost: FiniteStats::of(&r.source_cost),
        target_cost: FiniteStats::of(&r.target_cost),
        eigenpairs: s.basis.k().min(t.basis.k()),
        operator: OperatorUsed::of(&es.operator),
        maps: "source_to_target: per source vertex (upload numbering) its match on the target; target_to_source: \
               the reverse; *_cost: each match's distance in the spectral embedding; transferred (when asked): the \
               source's array on the target, labels by the vertex map, a function by the functional map",
    };
    // The head every result has: the source is the result's shape; warnings from the operator's parameters and
    // from the map itself.
    let mut warnings = operator_warnings(&summary.operator.parameters);
    if r.orthogonality_defect > MAP_DEFECT_WARN {
        warnings.push(Warning::new(
            "correspondence-not-isometric",
            format!(
                "the functional map is far from orthogonal (‖CCᵀ − I‖_F/√k = {:.2}, above {MAP_DEFECT_WARN}): the \
                 shapes are not near-isometric, or a partial match (a cut) went astray; give landmarks (three \
                 known pairs turned a wrong partial match, defect 0.47, into the exact one, defect 0.22)",
                r.orthogonality_defect
            ),
        ));
    }
    if options.orientation_weight > 0.0 && !r.oriented {
        warnings.push(Warning::new(
            "correspondence-orientation-not-applied",
            "the orientation term was left out: it needs triangle meshes enclosing a volume on both sides (closed, or \
             with small holes), and one side is an open surface, a cloud or a tetrahedral mesh; a shape with a mirror \
             symmetry may be matched to its mirror image (set orientation_weight to 0 to ask for no term)"
                .to_string(),
        ));
    }
    let head = ResultHead {
        shape_id: source.id.hex(),
        algorithm_version: ALGORITHM_VERSION,
        eigenpairs_reused: reused,
        warnings,
    };
    // Every number checked before the result is returned; each array's rows are one of the two shapes' vertices.
    let typed = Typed { head, body: Summary::Correspondence(Box::new(summary)) };
    // (An operator that leaves points out was refused above: every row has a value.)
    super::finite::checked_output(
        &typed,
        arrays,
        vec![],
        |a| Some(if a.name.starts_with("source_") { source } else { target }),
        0,
    )
}
