//! The engine alone, in process, without HTTP: opened on an embedded store in a temporary directory, a shape
//! stored, analyses submitted through the job engine, run by its dispatcher and runner on its pool, and their
//! results and failures read back. The numbers are checked against closed forms, not against kac's own output.

use clap::Parser;
use kac_core::descriptors::shape_dna::ShapeDnaOptions;
use kac_engine::analysis::{Analysis, SolverSpec};
use kac_engine::ids::{JobId, ShapeId};
use kac_engine::jobs::{self, JobView, Status};
use kac_engine::store::{ShapeRecord, StoredShape};
use kac_engine::{Code, Engine, EngineConfig, Metrics, NoMetrics};
use std::sync::atomic::{AtomicUsize, Ordering};
use std::sync::Arc;
use std::time::{Duration, Instant};

#[derive(Parser)]
struct Args {
    #[command(flatten)]
    config: EngineConfig,
}

fn open(dir: &std::path::Path, metrics: Arc<dyn Metrics>) -> Arc<Engine> {
    let args = Args::parse_from(["kac", "--data-dir", dir.to_str().unwrap(), "--workers", "2"]);
    // The statuses a host would give codes; the engine only passes them on (compare results).
    Engine::open(args.config, metrics, |_| 0).unwrap()
}

/// A level-3 icosphere stored as an upload would store it.
fn store_sphere(engine: &Engine) -> Arc<StoredShape> {
    let mesh = kac_core::geometry::generate::icosphere(3);
    let off = kac_core::io::write::off(&mesh).into_bytes();
    let validated =
        kac_core::load_bytes(&off, kac_core::Format::Off, &Default::default(), &Default::default()).unwrap();
    let record = ShapeRecord {
        id: validated.id.hex(),
        format: "off".into(),
        created_at: jobs::now(),
        bytes: off.len(),
        summary: serde_json::json!({ "vertices": validated.shape.vertex_count() }),
    };
    let (_, stored) = engine.shapes.insert(StoredShape { record, validated }, &off).unwrap();
    stored
}

fn wait(engine: &Engine, id: &str) -> JobView {
    let id = JobId::parse(id).unwrap();
    let until = Instant::now() + Duration::from_secs(120);
    loop {
        let view = engine.jobs.view(&id).unwrap().expect("the job is known");
        if view.status.terminal() {
            return view;
        }
        assert!(Instant::now() < until, "the job did not finish: {view:?}");
        std::thread::sleep(Duration::from_millis(20));
    }
}

struct Counted {
    jobs: AtomicUsize,
    solves: AtomicUsize,
}

impl Metrics for Counted {
    fn record_job(&self, _: &str, _: &str, _: f64) {
        self.jobs.fetch_add(1, Ordering::SeqCst);
    }
    fn record_solve(&self, _: &kac_core::spectrum::Stats) {
        self.solves.fetch_add(1, Ordering::SeqCst);
    }
}

/// A spectrum job runs through the dispatcher and the runner: the unit sphere's Laplace–Beltrami eigenvalues are
/// l(l+1) with multiplicity 2l+1 (0; 2 ×3; 6 ×5), which the level-3 icosphere resolves to within a few percent;
/// the result is stored and the metrics sink hears of the job and its eigensolve.
#[test]
fn the_runner_computes_a_spectrum_in_process() {
    let dir = tempfile::tempdir().unwrap();
    let metrics = Arc::new(Counted { jobs: AtomicUsize::new(0), solves: AtomicUsize::new(0) });
    let engine = open(dir.path(), metrics.clone());
    let shape = store_sphere(&engine);
    let request: Analysis = serde_json::from_value(serde_json::json!({ "analysis": "spectrum", "k": 9 })).unwrap();
    let (view, created) = jobs::submit(&engine.jobs, &engine.config, shape.clone(), request.clone()).unwrap();
    assert!(created);
    let done = wait(&engine, &view.id);
    assert_eq!(done.status, Status::Succeeded, "{done:?}");
    let result = engine.results.get(&JobId::parse(&view.id).unwrap()).unwrap().expect("the result is stored");
    let values: Vec<f64> = serde_json::from_value(result.summary["eigenvalues"].clone()).unwrap();
    let exact = [0.0, 2.0, 2.0, 2.0, 6.0, 6.0, 6.0, 6.0, 6.0];
    assert_eq!(values.len(), exact.len());
    assert!(values[0].abs() < 1e-8, "{values:?}");
    for (v, e) in values.iter().zip(exact).skip(1) {
        assert!((v - e).abs() / e < 0.05, "{values:?}");
    }
    assert_eq!(metrics.jobs.load(Ordering::SeqCst), 1);
    assert!(metrics.solves.load(Ordering::SeqCst) >= 1);
    // The same request is the same job.
    let (again, created) = jobs::submit(&engine.jobs, &engine.config, shape, request).unwrap();
    assert!(!created && again.id == view.id);
}

/// Refusals come back as the engine's errors with their codes, before anything is queued; a job that fails
/// records its failure with a code and no status.
#[test]
fn refusals_and_failures_carry_codes() {
    let dir = tempfile::tempdir().unwrap();
    let engine = open(dir.path(), Arc::new(NoMetrics));
    let shape = store_sphere(&engine);
    // More eigenpairs than --max-k (1000 by default).
    let too_many = Analysis::ShapeDna {
        options: ShapeDnaOptions { k: 5000, ..Default::default() },
        operator: Default::default(),
        solver: SolverSpec::default(),
    };
    match jobs::submit(&engine.jobs, &engine.config, shape.clone(), too_many) {
        Err(kac_engine::error::JobError::Limit(kac_engine::error::Limit::Pairs(m))) => assert!(m.contains("--max-k")),
        other => panic!("not refused for k: {other:?}"),
    }
    // Curvature of a graph has no meaning: refused by the truth table, with its code.
    let graph = kac_core::Shape::Graph(kac_core::geometry::generate::path_graph(5));
    let bytes = serde_json::to_vec(&kac_core::io::write::json(&graph)).unwrap();
    let validated =
        kac_core::load_bytes(&bytes, kac_core::Format::Json, &Default::default(), &Default::default()).unwrap();
    let record = ShapeRecord {
        id: validated.id.hex(),
        format: "json".into(),
        created_at: jobs::now(),
        bytes: bytes.len(),
        summary: serde_json::json!({}),
    };
    let (_, g) = engine.shapes.insert(StoredShape { record, validated }, &bytes).unwrap();
    match jobs::submit(&engine.jobs, &engine.config, g, Analysis::MeanCurvature {}) {
        Err(kac_engine::error::JobError::Analysis(e)) => assert_eq!(e.code(), Code::Unsupported, "{e}"),
        other => panic!("mean curvature of a graph was not refused: {other:?}"),
    }
    // A job whose shape is gone when it is claimed fails with internal-error, recorded without a status.
    let id = shape.record.id.clone();
    let request: Analysis = serde_json::from_value(serde_json::json!({ "analysis": "trees" })).unwrap();
    assert!(engine.shapes.remove(&ShapeId::parse(&id).unwrap()).unwrap());
    match jobs::submit(&engine.jobs, &engine.config, shape, request) {
        Ok((view, _)) => {
            let done = wait(&engine, &view.id);
            assert_eq!(done.status, Status::Failed, "{done:?}");
            let failure = done.error.expect("a failed job has its failure");
            assert_eq!(failure.code, Code::InternalError);
            let stored = serde_json::to_value(&failure).unwrap();
            assert!(stored.get("status").is_none(), "{stored}");
        }
        Err(e) => panic!("{e:?}"),
    }
}
