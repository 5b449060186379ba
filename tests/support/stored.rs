//! A mesh as the store keeps it: its OFF upload validated, with the record an upload would get.

use kac::service::store::{ShapeRecord, StoredShape};

/// The stored shape of `mesh` and its OFF bytes (the upload).
pub fn stored(mesh: &kac_core::geometry::TriangleMesh) -> (StoredShape, Vec<u8>) {
    let off = kac_core::io::write::off(mesh).into_bytes();
    let validated =
        kac_core::load_bytes(&off, kac_core::Format::Off, &Default::default(), &Default::default()).unwrap();
    let record = ShapeRecord {
        id: validated.id.hex(),
        format: "off".into(),
        created_at: "2026-01-01T00:00:00.000Z".into(),
        bytes: off.len(),
        summary: serde_json::json!({ "vertices": validated.shape.vertex_count() }),
    };
    (StoredShape { record, validated }, off)
}
