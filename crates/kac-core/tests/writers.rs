//! Writers round-trip: what kac writes, kac reads back to the same geometry (and the same id).

use kac_core::geometry::Shape;
use kac_core::io::write;
use kac_core::{load_bytes, Format, ReadOptions, ValidateOptions};

fn grid_mesh() -> Shape {
    // A 3×3-vertex grid with irrational-looking coordinates, to catch lossy number formatting.
    let mut vertices = Vec::new();
    for j in 0..3 {
        for i in 0..3 {
            vertices.push([i as f64 / 3.0 + 0.1f64.sqrt(), j as f64 * std::f64::consts::PI, (i * j) as f64 * 1e-7]);
        }
    }
    let mut faces = Vec::new();
    for j in 0..2u32 {
        for i in 0..2u32 {
            let a = j * 3 + i;
            faces.push([a, a + 1, a + 4]);
            faces.push([a, a + 4, a + 3]);
        }
    }
    Shape::TriangleMesh(kac_core::geometry::TriangleMesh { vertices, faces })
}

#[test]
fn off_obj_ply_json_round_trip_exactly() {
    let shape = grid_mesh();
    let Shape::TriangleMesh(mesh) = &shape else { unreachable!() };
    let outputs: Vec<(Format, Vec<u8>)> = vec![
        (Format::Off, write::off(mesh).into_bytes()),
        (Format::Obj, write::obj(&shape).into_bytes()),
        (Format::Ply, write::ply(&shape, false, None)),
        (Format::Ply, write::ply(&shape, true, None)),
        (Format::Ply, write::ply(&shape, true, Some(&[[1, 2, 3]; 9]))),
        (Format::Json, serde_json::to_vec(&write::json(&shape)).unwrap()),
    ];
    for (f, bytes) in outputs {
        let v = load_bytes(&bytes, f, &ReadOptions::default(), &ValidateOptions::default())
            .unwrap_or_else(|e| panic!("{f}: {e}"));
        assert_eq!(v.shape, shape, "{f} round trip");
        assert!(v.map_is_identity());
    }
}

#[test]
fn polyline_and_graph_round_trip_through_obj_and_json() {
    let poly = Shape::Polyline(kac_core::geometry::Polyline {
        vertices: vec![[0.0, 0.0, 0.0], [1.0, 0.5, 0.0], [2.0, 0.0, 0.25]],
        segments: vec![[0, 1], [1, 2]],
    });
    let v = load_bytes(write::obj(&poly).as_bytes(), Format::Obj, &ReadOptions::default(), &ValidateOptions::default())
        .unwrap();
    assert_eq!(v.shape, poly);
    let g = Shape::Graph(kac_core::geometry::Graph {
        vertex_count: 4,
        positions: None,
        edges: vec![[0, 1], [1, 2], [2, 3]],
        weights: vec![0.5, 2.0, 1.0],
    });
    let v = load_bytes(
        &serde_json::to_vec(&write::json(&g)).unwrap(),
        Format::Json,
        &ReadOptions::default(),
        &ValidateOptions::default(),
    )
    .unwrap();
    assert_eq!(v.shape, g);
}

/// The colour ramp spans the finite range (its ends at the minimum and the maximum), grey for NaN; and values
/// carried to input rows and back return unchanged, with the dropped input vertex NaN.
#[test]
fn colour_ramp_and_vertex_numbering_round_trip() {
    let c = kac_core::io::write::colour_ramp(&[2.0, f64::NAN, -1.0, 0.5]);
    assert_eq!(c, vec![[253, 231, 37], [128, 128, 128], [68, 1, 84], [33, 145, 140]]);
    // A square of two triangles with a duplicated corner (welded) and an unused vertex (dropped).
    let obj = "v 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nv 1 1 0\nv 5 5 5\nf 1 2 3\nf 1 5 4\n";
    let v = kac_core::load_bytes(
        obj.as_bytes(),
        kac_core::Format::Obj,
        &kac_core::ReadOptions::default(),
        &kac_core::ValidateOptions::default(),
    )
    .unwrap();
    let n = v.shape.vertex_count();
    assert_eq!((n, v.vertex_map.len()), (4, 6));
    let m = faer::Mat::from_fn(n, 2, |i, j| (10 * j + i) as f64);
    let rows = v.to_input_rows(m.as_ref(), |c| c.to_vec());
    assert_eq!(rows[2 * 2], rows[4 * 2], "welded input vertices share their value");
    assert!(rows[5 * 2].is_nan() && rows[5 * 2 + 1].is_nan(), "the dropped vertex is NaN");
    for j in 0..2 {
        let back = v.from_input_rows(&rows, 2, j);
        assert_eq!(back, (0..n).map(|i| m[(i, j)]).collect::<Vec<_>>());
    }
}
