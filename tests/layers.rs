//! The layers' boundaries, checked on the source: the stores (`src/service/store`) and the job engine
//! (`src/service/jobs`) import nothing from the HTTP layer (axum, the routes, the HTTP errors), so that the queue
//! and the engine can be used and tested without it (their unit tests run in process on an in-memory queue and a
//! manual clock); the numerical core has no HTTP in it at all.

use std::path::Path;

fn sources(dir: &Path) -> Vec<(String, String)> {
    let mut out = vec![];
    for e in std::fs::read_dir(dir).unwrap() {
        let p = e.unwrap().path();
        if p.is_dir() {
            out.extend(sources(&p));
        } else if p.extension().is_some_and(|x| x == "rs") {
            out.push((p.display().to_string(), std::fs::read_to_string(&p).unwrap()));
        }
    }
    out
}

fn uses(text: &str, needle: &str) -> bool {
    text.lines().filter(|l| !l.trim_start().starts_with("//")).any(|l| l.contains(needle))
}

#[test]
fn the_stores_import_nothing_from_the_http_layer() {
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let files = sources(&root.join("src/service/store"));
    assert!(files.len() >= 4, "the stores' sources");
    for (path, text) in files {
        for needle in ["axum", "service::error", "super::super::error", "routes::", "StatusCode", "ApiError"] {
            assert!(!uses(&text, needle), "{path} uses {needle}");
        }
    }
}

/// The job engine (`src/service/jobs`: submit, cancel, views, the dispatcher, the supervisor, the runner, its
/// clock) answers with its own error type, `JobError`, which the HTTP layer maps to problems, and records how a job
/// failed as a `Problem` (a data type of its own); it names no HTTP type.
#[test]
fn the_job_engine_imports_nothing_from_the_http_layer() {
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let mut files = sources(&root.join("src/service/jobs"));
    files
        .push(("src/service/compare.rs".into(), std::fs::read_to_string(root.join("src/service/compare.rs")).unwrap()));
    assert!(files.len() >= 4, "the engine's sources");
    for (path, text) in files {
        for needle in ["axum", "ApiError", "service::error", "super::error", "StatusCode", "routes::"] {
            assert!(!uses(&text, needle), "{path} uses {needle}");
        }
    }
}

#[test]
fn the_core_has_no_http() {
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    for (path, text) in sources(&root.join("crates/kac-core/src")) {
        for needle in ["axum", "hyper", "tower", "http::"] {
            assert!(!uses(&text, needle), "{path} uses {needle}");
        }
    }
}
