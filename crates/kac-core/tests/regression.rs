//! Regression tests named after what broke. Inputs found by the property tests and fuzz targets are kept here
//! (and under `fuzz/regressions/`) as ordinary tests.

use kac_core::{load_bytes, Format, ReadOptions, ShapeError, ValidateOptions};

/// gltf-json 1.4.1 panicked in its validation hook when a primitive's POSITION accessor index was out of range
/// (found by `mutated_valid_files_never_panic`). kac checks accessor references first.
#[test]
fn gltf_position_accessor_out_of_range_is_an_error_not_a_panic() {
    let doc =
        br#"{"asset":{"version":"2.0"},"meshes":[{"primitives":[{"attributes":{"POSITION":7}}]}],"accessors":[]}"#;
    match load_bytes(doc, Format::Gltf, &ReadOptions::default(), &ValidateOptions::default()) {
        Err(ShapeError::Syntax { message, .. }) => assert!(message.contains("accessor 7"), "{message}"),
        other => panic!("{other:?}"),
    }
}

/// Every file kept under fuzz/regressions reads to a shape or a typed error.
#[test]
fn fuzz_regressions_do_not_panic() {
    let dir = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../../fuzz/regressions");
    let entries: Vec<_> = std::fs::read_dir(&dir)
        .unwrap_or_else(|e| panic!("the fuzz regression corpus {} cannot be read: {e}", dir.display()))
        .flatten()
        .collect();
    assert!(!entries.is_empty(), "the fuzz regression corpus {} is empty", dir.display());
    for e in entries {
        let bytes = std::fs::read(e.path()).unwrap();
        for f in Format::ALL {
            let _ = load_bytes(&bytes, f, &ReadOptions::default(), &ValidateOptions::default());
        }
    }
}

/// sprs 0.11's Matrix Market reader panicked on an index outside the declared size (found by the mutation
/// property test); kac reads Matrix Market itself and names the entry and line.
#[test]
fn matrix_market_index_out_of_range_is_an_error_not_a_panic() {
    let mm = b"%%MatrixMarket matrix coordinate real symmetric\n3 3 3\n2 1 1.5\n3 9 2\n3 1 0.5\n";
    match load_bytes(mm, Format::Mtx, &ReadOptions::default(), &ValidateOptions::default()) {
        Err(ShapeError::IndexOutOfRange {
            index: 1, value: 8, location: kac_core::Location::Line { line: 4 }, ..
        }) => {}
        other => panic!("{other:?}"),
    }
    let v = load_bytes(
        b"%%MatrixMarket matrix coordinate pattern general\n3 3 4\n1 2\n2 1\n2 3\n3 2\n",
        Format::Mtx,
        &ReadOptions::default(),
        &ValidateOptions::default(),
    )
    .unwrap();
    let kac_core::Shape::Graph(g) = &v.shape else { panic!() };
    assert_eq!((g.vertex_count, g.edges.len()), (3, 2));
    assert_eq!(g.weights, vec![1.0, 1.0], "a general matrix is symmetrized as (A + Aᵀ)/2");
}

/// gltf 1.4.1's GLB parser underflowed on a declared length below the 12-byte header (found by the `gltf` fuzz
/// target, kept in fuzz/regressions); kac splits GLB containers itself.
#[test]
fn glb_declared_length_below_header_is_an_error_not_a_panic() {
    let glb = b"glTF\x22\xda\xda\x72\x07\x00\x00\x00";
    assert!(load_bytes(glb, Format::Glb, &ReadOptions::default(), &ValidateOptions::default()).is_err());
    let mut v2 = b"glTF\x02\x00\x00\x00\x07\x00\x00\x00".to_vec();
    v2.extend_from_slice(&[0; 8]);
    assert!(matches!(
        load_bytes(&v2, Format::Glb, &ReadOptions::default(), &ValidateOptions::default()),
        Err(ShapeError::Syntax { .. })
    ));
}
