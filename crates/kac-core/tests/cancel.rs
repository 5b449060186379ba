//! The stop flag takes effect in every phase of a solve: a progress callback raises the flag the moment a given
//! phase is reported, and the solve must then end with `Canceled` (not run on to a result). Phases are reported as
//! they start, so each test shows that a check follows the start of its phase.

use kac_core::geometry::generate;
use kac_core::geometry::Shape;
use kac_core::operators::{self, OperatorOptions};
use kac_core::spectrum::{eigs, Control, EigenError, EigenOptions, Method, Progress};
use std::sync::atomic::{AtomicBool, AtomicUsize, Ordering};
use std::sync::Mutex;

/// Solves with the flag raised at the `nth` report of `phase`; returns the outcome and every phase reported.
fn stop_at(shape: &Shape, opts: &EigenOptions, phase: &str, nth: usize) -> (Result<(), EigenError>, Vec<String>) {
    let o = operators::build(shape, &OperatorOptions::default()).unwrap();
    let stop = AtomicBool::new(false);
    let seen = AtomicUsize::new(0);
    let phases = Mutex::new(Vec::<String>::new());
    let progress = |p: Progress| {
        phases.lock().unwrap().push(p.phase.to_string());
        if p.phase == phase && seen.fetch_add(1, Ordering::SeqCst) + 1 == nth {
            stop.store(true, Ordering::SeqCst);
        }
    };
    let r =
        eigs(&o.pair, opts, None, Control { progress: Some(&progress), stop: Some(&stop), lender: None, farm: None })
            .map(|_| ());
    (r, phases.into_inner().unwrap())
}

#[test]
fn every_phase_of_the_sparse_solve_stops() {
    let shape = Shape::TriangleMesh(generate::icosphere(4));
    let opts = EigenOptions { k: 40, method: Method::Sparse, ..Default::default() };
    let (done, all) = stop_at(&shape, &opts, "none", 1);
    assert!(done.is_ok());
    for phase in ["null-space", "symbolic", "factorization", "iterating", "ritz-vectors", "verifying"] {
        assert!(all.iter().any(|p| p == phase), "{phase} is reported: {all:?}");
        let (r, seen) = stop_at(&shape, &opts, phase, 1);
        assert!(matches!(r, Err(EigenError::Canceled)), "{phase}: {r:?} after {seen:?}");
        // Nothing after the phase it stopped in starts.
        assert_eq!(seen.last().map(String::as_str), Some(phase), "{phase}: {seen:?}");
    }
    // Mid-iteration: at the second progress report of the block steps.
    let (r, _) = stop_at(&shape, &opts, "iterating", 2);
    assert!(matches!(r, Err(EigenError::Canceled)), "{r:?}");
}

#[test]
fn the_dense_path_stops_between_blocks() {
    // Forty separate spheres: the dense path solves block by block and checks between blocks.
    let mut parts = vec![];
    for i in 0..40 {
        let mut m = generate::icosphere(1);
        for p in &mut m.vertices {
            p[0] += 3.0 * i as f64;
        }
        parts.push(m);
    }
    let mut union = kac_core::geometry::TriangleMesh::default();
    for m in parts {
        let off = union.vertices.len() as u32;
        union.vertices.extend(m.vertices);
        union.faces.extend(m.faces.iter().map(|f| [f[0] + off, f[1] + off, f[2] + off]));
    }
    let shape = Shape::TriangleMesh(union);
    let opts = EigenOptions { k: 100, method: Method::Dense, ..Default::default() };
    let (done, all) = stop_at(&shape, &opts, "none", 1);
    assert!(done.is_ok() && all.iter().any(|p| p == "dense"), "{all:?}");
    let (r, seen) = stop_at(&shape, &opts, "dense", 1);
    assert!(matches!(r, Err(EigenError::Canceled)), "{r:?} after {seen:?}");
}

/// One dense decomposition cannot stop inside; with a stop flag it runs on a thread of its own and a stop ends the
/// solve at once (2,562 unknowns: about 2.7 s of dense work on one core here, stopped after 0.1 s).
#[test]
fn a_single_dense_decomposition_is_left_behind_on_stop() {
    let shape = Shape::TriangleMesh(generate::icosphere(4));
    let o = operators::build(&shape, &OperatorOptions::default()).unwrap();
    let stop = AtomicBool::new(false);
    let opts = EigenOptions { k: 10, method: Method::Dense, ..Default::default() };
    let r = std::thread::scope(|s| {
        s.spawn(|| {
            std::thread::sleep(std::time::Duration::from_millis(100));
            stop.store(true, Ordering::SeqCst);
        });
        eigs(&o.pair, &opts, None, Control { stop: Some(&stop), ..Control::default() }).map(|_| ())
    });
    assert!(matches!(r, Err(EigenError::Canceled)), "{r:?}");
}

/// Work left to a thread of its own: its result comes back, a stop leaves it at once, and its panic is raised in
/// the caller (where a job runner catches it), not lost with the thread.
#[test]
fn abandonable_work_returns_stops_and_carries_its_panic() {
    let stop = AtomicBool::new(false);
    let control = Control { stop: Some(&stop), ..Control::default() };
    assert_eq!(control.abandonable("test", || 42).unwrap(), 42);
    let t = std::time::Instant::now();
    let r = std::thread::scope(|s| {
        s.spawn(|| {
            std::thread::sleep(std::time::Duration::from_millis(100));
            stop.store(true, Ordering::SeqCst);
        });
        control.abandonable("test", || std::thread::sleep(std::time::Duration::from_secs(3)))
    });
    assert!(matches!(r, Err(EigenError::Canceled)) && t.elapsed() < std::time::Duration::from_secs(2), "{r:?}");
    stop.store(false, Ordering::SeqCst);
    let panicked = std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| {
        let _ = control.abandonable("test", || -> u8 { panic!("inside") });
    }));
    let message = panicked.unwrap_err().downcast_ref::<&str>().map(|s| s.to_string());
    assert_eq!(message.as_deref(), Some("inside"));
}
