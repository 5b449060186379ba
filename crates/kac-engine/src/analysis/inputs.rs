//! Bounded inputs: every per-vertex or per-element array and every vertex index an analysis request takes is checked
//! against its shape before anything is computed: the length (one value per vertex of the upload, one vector per
//! element), each value finite and within ±[`MAX_INPUT_MAGNITUDE`], each index a vertex validation kept, and no
//! vertex given two different values. A refusal names the parameter and its first offending element. The service
//! checks at submission (a 422 before anything is queued) and the runner again (the CLI's path, and any caller of
//! [`run`]). Depends on the request types and the validated shape only.

use super::*;
use kac_core::correspondence::CorrespondenceOptions;

/// The largest magnitude of a value given per vertex or per element. The analyses form squares and products of
/// these values with the operator's entries and sum them over the vertices (uᵀLu, uᵀMu, the M-norms of initial
/// data, M g, the coefficients Φᵀ M f): at 10¹⁰⁰ a square is 10²⁰⁰, which leaves a factor of 10¹⁰⁸ below f64's
/// 1.8 × 10³⁰⁸ for the operator's entries (cotan weights, masses, a mesh's scale) and sums over up to billions of
/// vertices. A value of 1e308 overflowed at once: a Poisson right-hand side or a transferred function gave a
/// result whose every value was NaN.
pub const MAX_INPUT_MAGNITUDE: f64 = 1e100;

/// A number as a person reads it: in full where that is short, in scientific notation where it is huge or tiny.
fn shown(x: f64) -> String {
    if x == 0.0 || !x.is_finite() || (1e-4..1e16).contains(&x.abs()) {
        format!("{x}")
    } else {
        format!("{x:e}")
    }
}

/// A value given for `name` at position `at` (an element of a list, or a vertex), refused unless finite and within
/// ±[`MAX_INPUT_MAGNITUDE`].
pub(super) fn check_value(name: &str, at: &str, x: f64) -> Result<(), AnalysisError> {
    if x.is_finite() && x.abs() <= MAX_INPUT_MAGNITUDE {
        return Ok(());
    }
    Err(AnalysisError::invalid_parameter(format!(
        "{name}: {at} is {}; give finite values within ±{MAX_INPUT_MAGNITUDE:e} (whose squares and products with the \
         operator stay finite)",
        shown(x)
    )))
}

/// A function given per vertex in the upload's numbering: one value per input vertex, each bounded.
pub fn check_per_vertex(v: &Validated, name: &str, values: &[f64]) -> Result<(), AnalysisError> {
    let n = v.vertex_map.len();
    if values.len() != n {
        return Err(AnalysisError::invalid_parameter(format!(
            "{name}: {} values for {n} input vertices (one per vertex of the upload)",
            values.len()
        )));
    }
    // A vertex validation dropped is never read (results written in the upload's numbering hold NaN there, and
    // may be sent back as inputs).
    values
        .iter()
        .enumerate()
        .filter(|&(i, _)| v.vertex_map[i] != u32::MAX)
        .try_for_each(|(i, &x)| check_value(name, &format!("value {i}"), x))
}

/// Vertex indices in the upload's numbering: each one a vertex validation kept.
pub fn check_vertices(v: &Validated, name: &str, list: &[u32]) -> Result<(), AnalysisError> {
    map_vertices(v, list, name).map(|_| ())
}

/// `[vertex, value]` pairs: each vertex kept by validation, each value bounded (`value` says whether the values
/// are numbers to bound), and no vertex (after welding) given two different values.
pub(super) fn check_pairs(v: &Validated, name: &str, pairs: &[(u32, f64)], value: bool) -> Result<(), AnalysisError> {
    let ids: Vec<u32> = pairs.iter().map(|p| p.0).collect();
    let at = map_vertices(v, &ids, name)?;
    let mut seen: std::collections::HashMap<usize, usize> = std::collections::HashMap::new();
    for (i, (&(vertex, x), &w)) in pairs.iter().zip(&at).enumerate() {
        if value {
            check_value(name, &format!("pair {i} (vertex {vertex})"), x)?;
        }
        match seen.get(&w) {
            Some(&j) if pairs[j].1 != x => {
                let welded = if pairs[j].0 == vertex { String::new() } else { " (welded into one)".into() };
                return Err(AnalysisError::invalid_parameter(format!(
                    "{name}: pairs {j} and {i} give vertex {} the values {} and {}{welded}: one value per vertex",
                    pairs[j].0,
                    shown(pairs[j].1),
                    shown(x)
                )));
            }
            Some(_) => {}
            None => {
                seen.insert(w, i);
            }
        }
    }
    Ok(())
}

/// The narrowest bump of initial data: its exponent −d²/(2w²) needs w² above f64's smallest numbers (a width of
/// 1e-200 gave 0/0 = NaN at the source itself).
pub const MIN_WIDTH: f64 = 1e-100;

/// Initial data: a function per vertex, or a source vertex (with a width within [[`MIN_WIDTH`],
/// [`MAX_INPUT_MAGNITUDE`]]).
pub(super) fn check_initial(v: &Validated, start: &InitialData) -> Result<(), AnalysisError> {
    if let Some(f) = &start.initial {
        check_per_vertex(v, "initial", f)?;
    }
    if let Some(s) = start.source {
        check_vertices(v, "source", &[s])?;
    }
    if let Some(w) = start.width {
        if !(MIN_WIDTH..=MAX_INPUT_MAGNITUDE).contains(&w) {
            return Err(AnalysisError::invalid_parameter(format!(
                "width = {}: give a width within [{MIN_WIDTH:e}, {MAX_INPUT_MAGNITUDE:e}]",
                shown(w)
            )));
        }
    }
    Ok(())
}

/// The elements of a mesh (triangles or tetrahedra), for per-element inputs.
pub(super) fn elements(shape: &Shape) -> Option<usize> {
    match shape {
        Shape::TriangleMesh(m) => Some(m.faces.len()),
        Shape::TetMesh(m) => Some(m.tets.len()),
        _ => None,
    }
}

/// The dimension of the manifold a shape's Laplacian hears: 2 for a surface (a triangle mesh, a cloud in R³ or the
/// plane unless told otherwise), 3 for a solid; None where only the operator would tell (a cloud in Rⁿ).
fn manifold_dimension(v: &Validated, operator: &OperatorSpec) -> Option<usize> {
    match &v.shape {
        Shape::TriangleMesh(_) => Some(2),
        Shape::TetMesh(_) => Some(3),
        Shape::PointCloud(c) => operator.intrinsic_dimension.or(c.ambient.is_none().then_some(2)),
        Shape::Graph(_) | Shape::Polyline(_) => None,
    }
}

/// Everything a correspondence request gives, before any eigensolve: the options (each step, weight and count in
/// range, landmarks that pair each vertex once), the operator (Neumann, order 1), the two shapes (surfaces, solids
/// or clouds, both of one dimension), the landmarks' vertices on each side and the array to transfer (one bounded
/// value per source vertex).
pub fn check_correspondence(
    source: &Validated,
    target: &Validated,
    options: &CorrespondenceOptions,
    operator: &OperatorSpec,
    transfer: Option<&correspond::Transfer>,
) -> Result<(), AnalysisError> {
    options.check()?;
    if operator.order != 1 || operator.boundary != BoundarySpec::Neumann || operator.dirichlet_vertices.is_some() {
        return Err(AnalysisError::invalid_parameter(
            "operator: correspondence maps vertices to vertices: give a Neumann operator of order 1",
        ));
    }
    for (v, which) in [(source, "source"), (target, "target")] {
        if !matches!(v.shape, Shape::TriangleMesh(_) | Shape::TetMesh(_) | Shape::PointCloud(_)) {
            return Err(AnalysisError::not_applicable(format!(
                "the {which} is a {}: a correspondence is between surfaces, solids or point clouds",
                v.shape.kind().as_str()
            )));
        }
    }
    if let (Some(a), Some(b)) = (manifold_dimension(source, operator), manifold_dimension(target, operator)) {
        if a != b {
            return Err(AnalysisError::not_applicable(format!(
                "the source is a {} of dimension {a} and the target a {} of dimension {b}: a correspondence maps \
                 shapes of one kind (two surfaces, two solids, or clouds sampling them), whose eigenvalues grow alike \
                 (Weyl's law); no map between a surface's eigenfunctions and a solid's is near-isometric",
                source.shape.kind().as_str(),
                target.shape.kind().as_str()
            )));
        }
    }
    let (ls, lt): (Vec<u32>, Vec<u32>) = options.landmarks.iter().copied().unzip();
    check_vertices(source, "landmarks (source)", &ls)?;
    check_vertices(target, "landmarks (target)", &lt)?;
    if let Some(t) = transfer {
        check_per_vertex(source, "transfer.values", &t.values)?;
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    fn load(shape: &Shape) -> Validated {
        let bytes = serde_json::to_vec(&kac_core::io::write::json(shape)).unwrap();
        kac_core::load_bytes(&bytes, kac_core::Format::Json, &Default::default(), &Default::default()).unwrap()
    }

    fn sphere() -> Validated {
        load(&Shape::TriangleMesh(kac_core::geometry::generate::icosphere(1)))
    }

    fn refused(r: Result<(), AnalysisError>) -> String {
        match r {
            Err(e @ AnalysisError::InvalidParameter(_)) => e.to_string(),
            other => panic!("{other:?}"),
        }
    }

    /// Per-vertex inputs of 1e308 overflowed at once (a Poisson solution of NaN everywhere, served as nulls):
    /// each is refused naming the parameter and the first value, as are wrong lengths and vertices that do not
    /// exist; values at the bound pass.
    #[test]
    fn a_dropped_vertex_s_value_is_not_read() {
        // The icosahedron with one vertex no face uses: validation drops it, and a result written in the upload's
        // numbering holds NaN there; sent back as an input, that NaN is not read.
        let mut off = kac_core::io::write::off(&kac_core::geometry::generate::icosphere(0));
        off = off.replacen("12 20 0", "13 20 0", 1);
        let at = off.find("\n3 ").unwrap();
        off.insert_str(at, "\n5 5 5");
        let v = kac_core::load_bytes(off.as_bytes(), kac_core::Format::Off, &Default::default(), &Default::default())
            .unwrap();
        assert_eq!((v.vertex_map.len(), v.vertex_map[12]), (13, u32::MAX));
        let mut g = vec![1.0; 13];
        g[12] = f64::NAN;
        let p = Analysis::Poisson { g: g.clone(), dirichlet_values: None, operator: Default::default() };
        assert!(p.check_inputs(&v).is_ok());
        g[3] = f64::NAN;
        let p = Analysis::Poisson { g, dirichlet_values: None, operator: Default::default() };
        assert!(refused(p.check_inputs(&v)).starts_with("g: value 3"));
    }

    #[test]
    fn per_vertex_inputs_are_bounded_and_named() {
        let v = sphere();
        let n = v.vertex_map.len();
        let poisson = |g: Vec<f64>| Analysis::Poisson { g, dirichlet_values: None, operator: Default::default() };
        let big = refused(poisson(vec![1e308; n]).check_inputs(&v));
        assert!(big.starts_with("g: value 0 is 1e308; give finite values within ±1e100"), "{big}");
        let mut g = vec![1.0; n];
        g[7] = -1e101;
        assert!(refused(poisson(g).check_inputs(&v)).starts_with("g: value 7 is -1e101"));
        assert!(refused(poisson(vec![0.0; n - 1]).check_inputs(&v)).contains(&format!("{} values for {n}", n - 1)));
        assert!(poisson(vec![MAX_INPUT_MAGNITUDE; n]).check_inputs(&v).is_ok());
        let values = vec![(0, 1.0), (3, 2.0), (0, 3.0)];
        let twice = Analysis::Interpolate { values, labels: vec![], operator: Default::default() };
        assert!(refused(twice.check_inputs(&v)).starts_with("values: pairs 0 and 2 give vertex 0"));
        let fixed = Some(vec![(1, 0.0), (n as u32, 1.0)]);
        let p = Analysis::Poisson { g: vec![0.0; n], dirichlet_values: fixed, operator: Default::default() };
        assert!(refused(p.check_inputs(&v)).starts_with(&format!("dirichlet_values: vertex {n} does not exist")));
        let heat = Analysis::Heat {
            k: 10,
            times: None,
            sources: vec![0, 99],
            method: HeatMethod::Spectral,
            steps: 1,
            operator: Default::default(),
            solver: Default::default(),
        };
        assert!(refused(heat.check_inputs(&v)).starts_with("sources: vertex 99"));
        let wave = Analysis::Wave {
            k: 10,
            times: vec![1.0],
            start: InitialData { initial: Some(vec![0.0; n]), source: None, width: None },
            velocity: Some(vec![f64::MAX; n]),
            operator: Default::default(),
            solver: Default::default(),
        };
        assert!(refused(wave.check_inputs(&v)).starts_with("velocity: value 0"));
        let bump = |width: f64| Analysis::Diffuse {
            times: vec![0.1],
            start: InitialData { initial: None, source: Some(0), width: Some(width) },
            diffusivity: 1.0,
            method: HeatMethod::Spectral,
            k: 10,
            steps: 1,
            operator: Default::default(),
            solver: Default::default(),
        };
        assert!(refused(bump(1e-200).check_inputs(&v)).starts_with("width = 1e-200"));
        assert!(refused(bump(-1.0).check_inputs(&v)).starts_with("width = -1"));
        assert!(bump(0.1).check_inputs(&v).is_ok());
        let field = vec![[0.0, 1e200, 0.0]; 80];
        assert!(refused(Analysis::Divergence { field, mass: None }.check_inputs(&v)).starts_with("field: element 0[1]"));
        let short = Analysis::Divergence { field: vec![[0.0; 3]; 79], mass: None };
        assert!(refused(short.check_inputs(&v)).starts_with("field: 79 vectors for 80 elements"));
    }

    /// A correspondence refuses what no pair of shapes could honour and what does not fit these two, naming the
    /// parameter: a transferred function of 1e308, landmarks past the shape, a surface against a solid.
    #[test]
    fn correspondence_inputs_are_named() {
        let s = sphere();
        let n = s.vertex_map.len();
        let o = CorrespondenceOptions::default();
        let op = OperatorSpec::default();
        let transfer = correspond::Transfer { values: vec![1e308; n], labels: false };
        let r = refused(check_correspondence(&s, &s, &o, &op, Some(&transfer)));
        assert!(r.starts_with("transfer.values: value 0 is 1e308"), "{r}");
        let o = CorrespondenceOptions { landmarks: vec![(0, n as u32)], ..Default::default() };
        assert!(refused(check_correspondence(&s, &s, &o, &op, None)).starts_with("landmarks (target): vertex"));
        let o = CorrespondenceOptions { refine_step: 0, ..Default::default() };
        let r = check_correspondence(&s, &s, &o, &op, None).unwrap_err().to_string();
        assert!(r.contains("refine_step"), "{r}");
        let solid = load(&Shape::TetMesh(kac_core::geometry::generate::unit_cube_tets(2)));
        let e = check_correspondence(&s, &solid, &CorrespondenceOptions::default(), &op, None).unwrap_err();
        assert_eq!(e.code().as_str(), "not-applicable");
        assert!(e.to_string().contains("triangle_mesh of dimension 2 and the target a tet_mesh"), "{e}");
        assert!(check_correspondence(&s, &s, &CorrespondenceOptions::default(), &op, None).is_ok());
    }
}
