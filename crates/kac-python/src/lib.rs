//! `kac._kac`: the native half of the Python package. It reads and validates shapes, runs every analysis of the
//! engine's registry from the same JSON requests the CLI and the service take, and hands arrays to NumPy. The
//! Python half (`python/kac`) gives these their keyword arguments, lapy's API and the HTTP client.
//!
//! Every computation runs on a thread of its own with the GIL released; the calling thread waits in slices of
//! 50 ms, checking Python's signals, so that Ctrl-C (KeyboardInterrupt) sets the engine's stop flag and the solve
//! ends at its next check (the eigensolver checks within its phases). An optional progress callback is called on
//! the calling thread, with the GIL, each time the phase or the count of converged pairs changes.

use kac_core::geometry::{Polygons, RawShape};
use kac_core::{Shape, ShapeError, ValidateOptions, Validated, Weld};
use kac_engine::analysis::{self, Analysis, AnalysisError, Hooks, Output};
use kac_engine::Code;
use numpy::{PyArray1, PyArray2, PyArrayMethods, PyReadonlyArray1, PyReadonlyArray2};
use pyo3::exceptions::PyException;
use pyo3::prelude::*;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Mutex};
use std::time::Duration;

pyo3::create_exception!(_kac, KacError, PyException, "A refusal or failure of kac, with its stable `code`.");

/// A `KacError` with its code, sentence and the members that go with the code (a dict).
fn kac_error(py: Python<'_>, code: Code, detail: String, extra: serde_json::Value) -> PyErr {
    let err = KacError::new_err(format!("{code}: {detail}"));
    let value = err.value(py);
    let _ = value.setattr("code", code.as_str());
    let _ = value.setattr("detail", detail);
    let _ = value.setattr("extra", json_to_py(py, &extra).unwrap_or_else(|_| py.None()));
    err
}

fn shape_error(py: Python<'_>, e: &ShapeError) -> PyErr {
    kac_error(py, Code::from(e), e.to_string(), serde_json::to_value(e).unwrap_or_default())
}

fn analysis_error(py: Python<'_>, e: &AnalysisError, analysis_name: Option<&str>) -> PyErr {
    // A refusal of the truth table says what does work: the analysis' row of the registry.
    let extra = match (e.code(), analysis_name) {
        (Code::Unsupported | Code::NotApplicable, Some(name)) => {
            serde_json::json!({ "supported": analysis::registry::table(None).analyses.iter()
                .find(|row| row.name == name) })
        }
        _ => serde_json::Value::Null,
    };
    kac_error(py, e.code(), e.to_string(), extra)
}

fn invalid(py: Python<'_>, detail: String) -> PyErr {
    kac_error(py, Code::InvalidRequest, detail, serde_json::Value::Null)
}

fn json_to_py(py: Python<'_>, v: &serde_json::Value) -> PyResult<PyObject> {
    let json = py.import("json")?;
    Ok(json.call_method1("loads", (v.to_string(),))?.unbind())
}

/// A validated shape: its canonical geometry, id, kind, validation report and the map from the input's vertices.
#[pyclass(frozen, module = "kac._kac")]
struct ValidatedShape {
    v: Arc<Validated>,
}

fn points_array<'py>(py: Python<'py>, points: &[[f64; 3]]) -> Bound<'py, PyArray2<f64>> {
    let flat: Vec<f64> = points.iter().flatten().copied().collect();
    PyArray1::from_vec(py, flat).reshape([points.len(), 3]).expect("n × 3")
}

fn index_array<'py, const N: usize>(py: Python<'py>, rows: &[[u32; N]]) -> Bound<'py, PyArray2<i64>> {
    let flat: Vec<i64> = rows.iter().flatten().map(|&i| i64::from(i)).collect();
    PyArray1::from_vec(py, flat).reshape([rows.len(), N]).expect("rows × N")
}

#[pymethods]
impl ValidatedShape {
    /// The vertices after validation (n × 3 float64; a graph without positions has none: 0 × 3).
    #[getter]
    fn vertices<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray2<f64>> {
        match &self.v.shape {
            Shape::TriangleMesh(m) => points_array(py, &m.vertices),
            Shape::TetMesh(m) => points_array(py, &m.vertices),
            Shape::PointCloud(c) => points_array(py, &c.points),
            Shape::Graph(g) => points_array(py, g.positions.as_deref().unwrap_or(&[])),
            Shape::Polyline(p) => points_array(py, &p.vertices),
        }
    }
    /// Triangles (m × 3 int64) of a triangle mesh; None otherwise.
    #[getter]
    fn faces<'py>(&self, py: Python<'py>) -> Option<Bound<'py, PyArray2<i64>>> {
        match &self.v.shape {
            Shape::TriangleMesh(m) => Some(index_array(py, &m.faces)),
            _ => None,
        }
    }
    /// Tetrahedra (m × 4 int64) of a tet mesh; None otherwise.
    #[getter]
    fn tets<'py>(&self, py: Python<'py>) -> Option<Bound<'py, PyArray2<i64>>> {
        match &self.v.shape {
            Shape::TetMesh(m) => Some(index_array(py, &m.tets)),
            _ => None,
        }
    }
    /// Edges of a graph or segments of a polyline (m × 2 int64); None otherwise.
    #[getter]
    fn edges<'py>(&self, py: Python<'py>) -> Option<Bound<'py, PyArray2<i64>>> {
        match &self.v.shape {
            Shape::Graph(g) => Some(index_array(py, &g.edges)),
            Shape::Polyline(p) => Some(index_array(py, &p.segments)),
            _ => None,
        }
    }
    /// `triangle_mesh`, `tet_mesh`, `point_cloud`, `graph` or `polyline`.
    #[getter]
    fn kind(&self) -> &'static str {
        self.v.shape.kind().as_str()
    }
    /// The shape id: SHA-256 of the canonical geometry (the service's id of the same upload).
    #[getter]
    fn id(&self) -> String {
        self.v.id.hex()
    }
    /// The validation report (what was repaired, dropped or warned), as a dict.
    #[getter]
    fn report(&self, py: Python<'_>) -> PyResult<PyObject> {
        json_to_py(py, &serde_json::to_value(&self.v.report).unwrap_or_default())
    }
    /// For each input vertex, its index among `vertices`, or -1 where validation dropped it.
    #[getter]
    fn vertex_map<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray1<i64>> {
        let map: Vec<i64> = self.v.vertex_map.iter().map(|&i| if i == u32::MAX { -1 } else { i64::from(i) }).collect();
        PyArray1::from_vec(py, map)
    }
    /// The number of input vertices (the rows of every per-vertex array kac returns).
    #[getter]
    fn input_vertices(&self) -> usize {
        self.v.vertex_map.len()
    }
    fn __repr__(&self) -> String {
        format!("<kac shape {} {}, {} vertices>", self.kind(), &self.id()[..12], self.v.shape.vertex_count())
    }
}

fn weld_of(py: Python<'_>, weld: &str) -> PyResult<Weld> {
    match weld {
        "exact" => Ok(Weld::Exact),
        "none" => Ok(Weld::None),
        t => match t.parse::<f64>() {
            Ok(v) if v > 0.0 && v.is_finite() => Ok(Weld::Tolerance(v)),
            _ => Err(invalid(py, format!("weld={t:?}: give \"exact\", \"none\" or a positive distance"))),
        },
    }
}

/// Reads and validates a shape file (any format kac reads; `format` overrides the extension and the content).
#[pyfunction]
#[pyo3(signature = (path, format=None, weld="exact", keep_degenerate=false))]
fn read(
    py: Python<'_>,
    path: std::path::PathBuf,
    format: Option<&str>,
    weld: &str,
    keep_degenerate: bool,
) -> PyResult<ValidatedShape> {
    let format =
        match format {
            None => None,
            Some(name) => Some(kac_core::Format::from_name(name).ok_or_else(|| {
                invalid(py, format!("unknown format '{name}'; one of: {}", kac_core::Format::names()))
            })?),
        };
    let validate = ValidateOptions { weld: weld_of(py, weld)?, drop_degenerate: !keep_degenerate, kind: None };
    let loaded = py.allow_threads(|| kac_core::load(&path, format, &Default::default(), &validate));
    let (v, _) = loaded.map_err(|e| shape_error(py, &e))?;
    Ok(ValidatedShape { v: Arc::new(v) })
}

fn rows<const N: usize>(
    py: Python<'_>,
    what: &str,
    a: &PyReadonlyArray2<'_, i64>,
    n: usize,
) -> PyResult<Vec<[u32; N]>> {
    let view = a.as_array();
    if view.ncols() != N {
        return Err(invalid(py, format!("{what} has {} columns, not {N}", view.ncols())));
    }
    let mut out = Vec::with_capacity(view.nrows());
    for (r, row) in view.rows().into_iter().enumerate() {
        let mut item = [0u32; N];
        for (c, &i) in row.iter().enumerate() {
            if i < 0 || i as u64 >= n as u64 {
                return Err(kac_error(
                    py,
                    Code::IndexOutOfRange,
                    format!("{what}[{r}] refers to vertex {i}, and there are {n} vertices"),
                    serde_json::json!({ "element": what, "index": r, "value": i }),
                ));
            }
            item[c] = i as u32;
        }
        out.push(item);
    }
    Ok(out)
}

/// A shape from arrays: vertices (n × 3, or n × d for a point cloud in Rᵈ) and at most one of faces (m × 3),
/// tets (m × 4) or edges (m × 2, with optional weights); none of them: a point cloud. Validated as an upload
/// is (by default without welding, so that rows stay the caller's vertices).
#[pyfunction]
#[pyo3(signature = (vertices, faces=None, tets=None, edges=None, weights=None, graph=false, weld="none", keep_degenerate=false))]
#[allow(clippy::too_many_arguments)]
fn from_arrays(
    py: Python<'_>,
    vertices: PyReadonlyArray2<'_, f64>,
    faces: Option<PyReadonlyArray2<'_, i64>>,
    tets: Option<PyReadonlyArray2<'_, i64>>,
    edges: Option<PyReadonlyArray2<'_, i64>>,
    weights: Option<PyReadonlyArray1<'_, f64>>,
    graph: bool,
    weld: &str,
    keep_degenerate: bool,
) -> PyResult<ValidatedShape> {
    let v = vertices.as_array();
    let (n, d) = (v.nrows(), v.ncols());
    if !(2..=3).contains(&d) && (faces.is_some() || tets.is_some() || edges.is_some() || d < 2) {
        return Err(invalid(
            py,
            format!("vertices are {n} × {d}: give n × 3 (or n × 2, or n × d ≥ 4 for a point cloud)"),
        ));
    }
    for (r, row) in v.rows().into_iter().enumerate() {
        if let Some(x) = row.iter().find(|x| !x.is_finite()) {
            return Err(kac_error(
                py,
                Code::NonFiniteValue,
                format!("vertex {r} has the coordinate {x}"),
                serde_json::json!({ "element": "vertex", "index": r }),
            ));
        }
    }
    let mut raw = RawShape {
        vertices: v.rows().into_iter().map(|r| [r[0], r[1], if d > 2 { r[2] } else { 0.0 }]).collect(),
        planar_input: d == 2,
        ..Default::default()
    };
    if d >= 4 {
        let ambient: Vec<f64> = v.iter().copied().collect();
        raw.ambient = Some(kac_core::geometry::Ambient { dim: d, coords: ambient });
    }
    let given = [faces.is_some(), tets.is_some(), edges.is_some()].iter().filter(|&&g| g).count();
    if given > 1 {
        return Err(invalid(py, "give at most one of faces, tets and edges".into()));
    }
    if let Some(f) = &faces {
        raw.polygons = Polygons::from_triangles(&rows::<3>(py, "faces", f, n)?);
    }
    if let Some(t) = &tets {
        raw.tets = rows::<4>(py, "tets", t, n)?;
    }
    if let Some(e) = &edges {
        raw.segments = rows::<2>(py, "edges", e, n)?;
        raw.is_graph = graph || weights.is_some();
        if let Some(w) = &weights {
            let w: Vec<f64> = w.as_array().iter().copied().collect();
            if w.len() != raw.segments.len() {
                return Err(invalid(py, format!("{} weights for {} edges", w.len(), raw.segments.len())));
            }
            raw.weights = Some(w);
        }
    }
    let validate = ValidateOptions { weld: weld_of(py, weld)?, drop_degenerate: !keep_degenerate, kind: None };
    let v = py.allow_threads(|| kac_core::validate(raw, &validate)).map_err(|e| shape_error(py, &e))?;
    Ok(ValidatedShape { v: Arc::new(v) })
}

/// Progress as the engine reports it: (phase, converged, wanted).
type Seen = Arc<Mutex<Option<(String, usize, usize)>>>;

/// Runs `work` on a thread of its own with the GIL released, waiting in 50 ms slices: a signal (Ctrl-C) sets the
/// stop flag and waits for the work to stop; `progress` is called when what the work reports changes.
fn interruptible<T: Send + 'static>(
    py: Python<'_>,
    progress: Option<&Bound<'_, PyAny>>,
    work: impl FnOnce(&AtomicBool, &(dyn Fn(kac_core::spectrum::Progress) + Sync)) -> T + Send + 'static,
) -> PyResult<T> {
    let stop = Arc::new(AtomicBool::new(false));
    let seen: Seen = Arc::new(Mutex::new(None));
    let (tx, rx) = std::sync::mpsc::channel();
    // Waited on with the GIL released, from this thread only.
    let rx = Mutex::new(rx);
    let (s, p) = (stop.clone(), seen.clone());
    std::thread::Builder::new()
        .name("kac-python".into())
        .spawn(move || {
            let report = move |pr: kac_core::spectrum::Progress| {
                *p.lock().unwrap_or_else(|e| e.into_inner()) = Some((pr.phase.to_string(), pr.converged, pr.wanted));
            };
            let out = std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| work(&s, &report)));
            let _ = tx.send(out);
        })
        .map_err(|e| PyException::new_err(format!("cannot start a thread: {e}")))?;
    let mut last: Option<(String, usize, usize)> = None;
    loop {
        let got =
            py.allow_threads(|| rx.lock().unwrap_or_else(|e| e.into_inner()).recv_timeout(Duration::from_millis(50)));
        match got {
            Ok(Ok(out)) => return Ok(out),
            Ok(Err(panic)) => {
                let msg = panic
                    .downcast_ref::<String>()
                    .cloned()
                    .or_else(|| panic.downcast_ref::<&str>().map(|s| s.to_string()))
                    .unwrap_or_default();
                return Err(kac_error(
                    py,
                    Code::JobPanicked,
                    format!("the computation panicked: {msg}"),
                    serde_json::Value::Null,
                ));
            }
            Err(std::sync::mpsc::RecvTimeoutError::Disconnected) => {
                return Err(kac_error(
                    py,
                    Code::InternalError,
                    "the computation's thread ended".into(),
                    serde_json::Value::Null,
                ))
            }
            Err(std::sync::mpsc::RecvTimeoutError::Timeout) => {}
        }
        // A signal (Ctrl-C), or an exception of the progress callback, stops the work: it ends at its next check
        // of the flag, and its result is dropped.
        let mut raised = py.check_signals().err();
        if let (None, Some(cb)) = (&raised, progress) {
            let now = seen.lock().unwrap_or_else(|e| e.into_inner()).clone();
            if now.is_some() && now != last {
                if let Some((phase, converged, wanted)) = &now {
                    raised = cb.call1((phase.as_str(), *converged, *wanted)).err();
                }
                last = now;
            }
        }
        if let Some(e) = raised {
            stop.store(true, Ordering::SeqCst);
            let _ = py.allow_threads(|| rx.lock().unwrap_or_else(|e| e.into_inner()).recv());
            return Err(e);
        }
    }
}

/// Runs `f` on a pool of `threads` threads (0: rayon's global pool).
fn on_pool<T: Send>(threads: usize, f: impl FnOnce() -> T + Send) -> T {
    if threads == 0 {
        return f();
    }
    match rayon::ThreadPoolBuilder::new().num_threads(threads).build() {
        Ok(pool) => pool.install(f),
        Err(_) => f(),
    }
}

/// An output for Python: (summary as JSON text, [(name, rows × cols array, columns or None)]).
type PyOutput = (String, Vec<(String, Py<PyArray2<f64>>, Option<Vec<f64>>)>);

fn to_python(py: Python<'_>, out: Output) -> PyResult<PyOutput> {
    let mut arrays = vec![];
    for a in out.arrays {
        let (rows, cols) = (a.rows, a.cols.max(1));
        let arr = PyArray1::from_vec(py, a.data).reshape([rows, cols])?;
        arrays.push((a.name.to_string(), arr.unbind(), a.columns));
    }
    Ok((out.summary.to_string(), arrays))
}

/// Runs one analysis of the registry: `request` is its JSON (`{"analysis": "hks", …}`), as the CLI and the
/// service take it; the answer is the summary as JSON text and the arrays, rows in the input's vertex numbering.
#[pyfunction]
#[pyo3(signature = (shape, request, threads=0, progress=None))]
fn run(
    py: Python<'_>,
    shape: &ValidatedShape,
    request: &str,
    threads: usize,
    progress: Option<Bound<'_, PyAny>>,
) -> PyResult<PyOutput> {
    let a: Analysis = serde_json::from_str(request).map_err(|e| invalid(py, format!("the request: {e}")))?;
    let name = a.name();
    let v = shape.v.clone();
    let out = interruptible(py, progress.as_ref(), move |stop, report| {
        on_pool(threads, || {
            let control =
                kac_core::spectrum::Control { stop: Some(stop), progress: Some(report), ..Default::default() };
            analysis::run(&v, &a, Hooks { control, threads, ..Default::default() })
        })
    })?;
    to_python(py, out.map_err(|e| analysis_error(py, &e, Some(name)))?)
}

/// The correspondence of two shapes: `request` is the JSON of the service's correspondence request without the
/// shape ids (options at the top level, `operator`, `transfer`).
#[pyfunction]
#[pyo3(signature = (source, target, request, threads=0, progress=None))]
fn correspond(
    py: Python<'_>,
    source: &ValidatedShape,
    target: &ValidatedShape,
    request: &str,
    threads: usize,
    progress: Option<Bound<'_, PyAny>>,
) -> PyResult<PyOutput> {
    let mut value: serde_json::Value =
        serde_json::from_str(request).map_err(|e| invalid(py, format!("the request: {e}")))?;
    if let Some(m) = value.as_object_mut() {
        m.insert("source_id".into(), source.v.id.hex().into());
        m.insert("target_id".into(), target.v.id.hex().into());
    }
    let req: kac_engine::correspondence::CorrespondenceRequest =
        serde_json::from_value(value).map_err(|e| invalid(py, format!("the request: {e}")))?;
    let (s, t) = (source.v.clone(), target.v.clone());
    let out = interruptible(py, progress.as_ref(), move |stop, report| {
        on_pool(threads, || {
            let control =
                kac_core::spectrum::Control { stop: Some(stop), progress: Some(report), ..Default::default() };
            kac_engine::correspondence::run(&s, &t, &req, Hooks { control, threads, ..Default::default() })
        })
    })?;
    to_python(py, out.map_err(|e| analysis_error(py, &e, Some("correspondence")))?)
}

/// Shape-DNA distances between shapes: `request` is the JSON of the service's compare request without the
/// shape ids. The answer's summary lists the distances, each shape's nearest and the shapes that failed.
#[pyfunction]
#[pyo3(signature = (shapes, request, threads=0, progress=None))]
fn compare(
    py: Python<'_>,
    shapes: Vec<PyRef<'_, ValidatedShape>>,
    request: &str,
    threads: usize,
    progress: Option<Bound<'_, PyAny>>,
) -> PyResult<PyOutput> {
    let req: kac_engine::compare::CompareRequest =
        serde_json::from_str(request).map_err(|e| invalid(py, format!("the request: {e}")))?;
    let stored: Vec<Arc<kac_engine::store::StoredShape>> = shapes
        .iter()
        .map(|s| {
            Arc::new(kac_engine::store::StoredShape {
                record: kac_engine::store::ShapeRecord {
                    id: s.v.id.hex(),
                    format: String::new(),
                    created_at: String::new(),
                    bytes: 0,
                    summary: serde_json::Value::Null,
                },
                validated: (*s.v).clone(),
            })
        })
        .collect();
    let out = interruptible(py, progress.as_ref(), move |stop, report| {
        on_pool(threads, || {
            let control =
                kac_core::spectrum::Control { stop: Some(stop), progress: Some(report), ..Default::default() };
            // Statuses are the service's; here each failure carries its code only.
            kac_engine::compare::run(&stored, &req, None, Hooks { control, threads, ..Default::default() }, |_| 0)
        })
    })?;
    to_python(py, out.map_err(|e| analysis_error(py, &e, Some("compare")))?)
}

/// The registry of analyses (where each is valid), as JSON text: the same table as `kac analyses`.
#[pyfunction]
fn analyses() -> String {
    serde_json::to_string(&analysis::registry::table(None)).unwrap_or_default()
}

/// Every stable problem code with its description.
#[pyfunction]
fn codes() -> Vec<(&'static str, &'static str)> {
    Code::ALL.iter().map(|c| (c.as_str(), c.describe())).collect()
}

/// The JSON Schemas of the requests, from the service's OpenAPI document (the one vocabulary of option names).
#[pyfunction]
fn openapi() -> &'static str {
    include_str!("../../../openapi/openapi.json")
}

#[pymodule]
fn _kac(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add("KacError", m.py().get_type::<KacError>())?;
    m.add("__version__", env!("CARGO_PKG_VERSION"))?;
    m.add_class::<ValidatedShape>()?;
    m.add_function(wrap_pyfunction!(read, m)?)?;
    m.add_function(wrap_pyfunction!(from_arrays, m)?)?;
    m.add_function(wrap_pyfunction!(run, m)?)?;
    m.add_function(wrap_pyfunction!(correspond, m)?)?;
    m.add_function(wrap_pyfunction!(compare, m)?)?;
    m.add_function(wrap_pyfunction!(analyses, m)?)?;
    m.add_function(wrap_pyfunction!(codes, m)?)?;
    m.add_function(wrap_pyfunction!(openapi, m)?)?;
    Ok(())
}
