//! Writers: OFF, OBJ and PLY (ASCII and binary little-endian) for surfaces, PLY for point clouds, OBJ `l` lines
//! for polylines, and kac JSON for every kind. Numbers are written with Rust's shortest round-trip formatting,
//! so reading a written file gives back the same f64 coordinates.

use crate::geometry::{Shape, TriangleMesh};
use std::fmt::Write as _;

/// OFF text of a triangle mesh.
pub fn off(mesh: &TriangleMesh) -> String {
    let mut s = String::with_capacity(40 * mesh.vertices.len() + 24 * mesh.faces.len());
    let _ = writeln!(s, "OFF\n{} {} 0", mesh.vertices.len(), mesh.faces.len());
    for v in &mesh.vertices {
        let _ = writeln!(s, "{:?} {:?} {:?}", v[0], v[1], v[2]);
    }
    for f in &mesh.faces {
        let _ = writeln!(s, "3 {} {} {}", f[0], f[1], f[2]);
    }
    s
}

/// OBJ text of a surface or polyline (other kinds: vertices only).
pub fn obj(shape: &Shape) -> String {
    let mut s = String::from("# written by kac\n");
    if let Some(p) = shape.positions() {
        for v in p {
            let _ = writeln!(s, "v {:?} {:?} {:?}", v[0], v[1], v[2]);
        }
    }
    match shape {
        Shape::TriangleMesh(m) => m.faces.iter().for_each(|f| {
            let _ = writeln!(s, "f {} {} {}", f[0] + 1, f[1] + 1, f[2] + 1);
        }),
        Shape::Polyline(p) => p.segments.iter().for_each(|e| {
            let _ = writeln!(s, "l {} {}", e[0] + 1, e[1] + 1);
        }),
        _ => {}
    }
    s
}

/// PLY of a surface (faces) or any shape's vertices, ASCII or binary little-endian, with optional per-vertex
/// RGB colours.
pub fn ply(shape: &Shape, binary: bool, colors: Option<&[[u8; 3]]>) -> Vec<u8> {
    let empty: Vec<[f64; 3]> = Vec::new();
    let verts = shape.positions().unwrap_or(&empty);
    let faces: &[[u32; 3]] = match shape {
        Shape::TriangleMesh(m) => &m.faces,
        _ => &[],
    };
    let mut h = String::from("ply\n");
    h.push_str(if binary { "format binary_little_endian 1.0\n" } else { "format ascii 1.0\n" });
    h.push_str("comment written by kac\n");
    let _ = writeln!(h, "element vertex {}", verts.len());
    h.push_str("property double x\nproperty double y\nproperty double z\n");
    if colors.is_some() {
        h.push_str("property uchar red\nproperty uchar green\nproperty uchar blue\n");
    }
    if !faces.is_empty() {
        let _ = writeln!(h, "element face {}", faces.len());
        h.push_str("property list uchar int vertex_indices\n");
    }
    h.push_str("end_header\n");
    let mut out = h.into_bytes();
    if binary {
        out.reserve(27 * verts.len() + 13 * faces.len());
        for (i, v) in verts.iter().enumerate() {
            for c in v {
                out.extend_from_slice(&c.to_le_bytes());
            }
            if let Some(c) = colors {
                out.extend_from_slice(&c[i]);
            }
        }
        for f in faces {
            out.push(3);
            for i in f {
                out.extend_from_slice(&(*i as i32).to_le_bytes());
            }
        }
    } else {
        let mut s = String::new();
        for (i, v) in verts.iter().enumerate() {
            let _ = write!(s, "{:?} {:?} {:?}", v[0], v[1], v[2]);
            if let Some(c) = colors {
                let _ = write!(s, " {} {} {}", c[i][0], c[i][1], c[i][2]);
            }
            s.push('\n');
        }
        for f in faces {
            let _ = writeln!(s, "3 {} {} {}", f[0], f[1], f[2]);
        }
        out.extend_from_slice(s.as_bytes());
    }
    out
}

/// kac JSON of any shape (readable by the `json` reader).
pub fn json(shape: &Shape) -> serde_json::Value {
    use serde_json::json;
    match shape {
        Shape::TriangleMesh(m) => json!({ "vertices": m.vertices, "faces": m.faces }),
        Shape::TetMesh(m) => json!({ "vertices": m.vertices, "tets": m.tets }),
        Shape::PointCloud(c) => match &c.normals {
            Some(n) => json!({ "vertices": c.points, "normals": n }),
            None => json!({ "vertices": c.points }),
        },
        Shape::Polyline(p) => json!({ "vertices": p.vertices, "segments": p.segments }),
        Shape::Graph(g) => match &g.positions {
            Some(p) => json!({ "vertices": p, "edges": g.edges, "weights": g.weights }),
            None => json!({ "vertex_count": g.vertex_count, "edges": g.edges, "weights": g.weights }),
        },
    }
}

/// Colours for per-vertex values: a viridis-like ramp (dark blue → yellow, five stops interpolated linearly) over
/// the finite range of `values`, grey for NaN or infinite values.
pub fn colour_ramp(values: &[f64]) -> Vec<[u8; 3]> {
    const RAMP: [[f64; 3]; 5] =
        [[68.0, 1.0, 84.0], [59.0, 82.0, 139.0], [33.0, 145.0, 140.0], [94.0, 201.0, 98.0], [253.0, 231.0, 37.0]];
    let (lo, hi) =
        values.iter().filter(|x| x.is_finite()).fold((f64::MAX, f64::MIN), |(l, h), &x| (l.min(x), h.max(x)));
    values
        .iter()
        .map(|&x| {
            if !x.is_finite() {
                return [128, 128, 128];
            }
            let t = if hi > lo { (x - lo) / (hi - lo) } else { 0.5 } * 4.0;
            let i = (t.floor() as usize).min(3);
            let f = t - i as f64;
            let c = |k: usize| (RAMP[i][k] * (1.0 - f) + RAMP[i + 1][k] * f).round() as u8;
            [c(0), c(1), c(2)]
        })
        .collect()
}
