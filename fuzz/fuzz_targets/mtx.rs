//! Fuzz target: the mtx reader and the validator never panic; a shape that validates writes and reads back
//! as OFF with the same id (for surfaces).
#![no_main]
use kac_core::{load_bytes, Format, ReadOptions, ValidateOptions};
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    let opts = ReadOptions { max_vertices: 1 << 20, max_elements: 1 << 21 };
    if let Ok(v) = load_bytes(data, Format::Mtx, &opts, &ValidateOptions::default()) {
        if let kac_core::Shape::TriangleMesh(m) = &v.shape {
            let text = kac_core::io::write::off(m);
            let back = load_bytes(text.as_bytes(), Format::Off, &opts, &ValidateOptions::default()).expect("written OFF reads back");
            assert_eq!(back.id, v.id, "OFF round trip keeps the id");
        }
    }
});
