//! Shared helpers of the integration tests (the core's, and the service's through `#[path]`): the one configurable
//! location of the shared test meshes.
#![allow(dead_code)]

use std::path::PathBuf;

/// `KAC_DATA_DIR`, or `../shared/data` beside the repository (the workspace root is the ancestor of the calling
/// crate that holds `Cargo.lock`).
pub fn data_dir() -> Option<PathBuf> {
    let dir = match std::env::var_os("KAC_DATA_DIR") {
        Some(d) => PathBuf::from(d),
        None => {
            let manifest = std::path::Path::new(env!("CARGO_MANIFEST_DIR"));
            let root = manifest.ancestors().find(|a| a.join("Cargo.lock").is_file()).unwrap_or(manifest);
            root.join("../shared/data")
        }
    };
    dir.join("README.md").is_file().then_some(dir)
}

/// The shared data directory, or `None` after printing why the calling test is skipped.
pub fn data_or_skip(test: &str) -> Option<PathBuf> {
    let d = data_dir();
    if d.is_none() {
        eprintln!("SKIP {test}: shared test data not found (set KAC_DATA_DIR or check out ../shared/data)");
    }
    d
}
