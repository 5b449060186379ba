//! Shared helpers of the integration tests (the core's, and the service's through `#[path]`): the one configurable
//! location of the shared test meshes.
#![allow(dead_code)]

use std::path::PathBuf;

/// `KAC_TEST_DATA` (or `KAC_DATA_DIR`), or `../shared/data` beside the repository (the workspace root is the ancestor of the calling
/// crate that holds `Cargo.lock`).
pub fn data_dir() -> Option<PathBuf> {
    let dir = match std::env::var_os("KAC_TEST_DATA").or_else(|| std::env::var_os("KAC_DATA_DIR")) {
        Some(d) => PathBuf::from(d),
        None => {
            let manifest = std::path::Path::new(env!("CARGO_MANIFEST_DIR"));
            let root = manifest.ancestors().find(|a| a.join("Cargo.lock").is_file()).unwrap_or(manifest);
            root.join("../shared/data")
        }
    };
    dir.join("README.md").is_file().then_some(dir)
}

/// The shared data directory for a test that needs it. Such tests are `#[ignore]`d, so a plain `cargo test`
/// reports them as ignored through the harness; `scripts/test-all.sh` runs them (`-- --ignored`) wherever the
/// data is, and there a missing directory fails them instead of skipping.
pub fn shared_data(test: &str) -> PathBuf {
    data_dir().unwrap_or_else(|| {
        panic!("{test}: the shared test data is not at KAC_TEST_DATA or ../shared/data (run it where the data is)")
    })
}
