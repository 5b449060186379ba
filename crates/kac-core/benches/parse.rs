//! Parsing speed and memory of a 1M-triangle mesh as binary PLY (float32 and float64), OBJ and ASCII STL.
//! Run: `cargo bench -p kac-core --bench parse` (prints a Markdown table; `bench/parse.sh` writes it into
//! BENCHMARKS.md). Peak memory is measured in a child process: the growth of VmHWM during the parse, compared
//! with the bytes of the arrays the parse returns.

use kac_core::geometry::{generate, RawShape, TriangleMesh};
use kac_core::io::{self, Format, ReadOptions};
use std::time::Instant;

fn mesh() -> TriangleMesh {
    // 708 × 707 squares → 1,001,112 triangles, 502,152 vertices; a wavy height so coordinates are not round.
    let mut m = generate::grid(708, 707, 1.0, 1.0);
    for p in m.vertices.iter_mut() {
        p[2] = 0.05 * (7.0 * p[0]).sin() * (5.0 * p[1]).cos();
    }
    m
}

fn ply_f32(m: &TriangleMesh) -> Vec<u8> {
    let mut out = format!(
        "ply\nformat binary_little_endian 1.0\nelement vertex {}\nproperty float x\nproperty float y\nproperty float z\nelement face {}\nproperty list uchar int vertex_indices\nend_header\n",
        m.vertices.len(),
        m.faces.len()
    )
    .into_bytes();
    for v in &m.vertices {
        for c in v {
            out.extend_from_slice(&(*c as f32).to_le_bytes());
        }
    }
    for f in &m.faces {
        out.push(3);
        for i in f {
            out.extend_from_slice(&(*i as i32).to_le_bytes());
        }
    }
    out
}

fn stl_ascii(m: &TriangleMesh) -> Vec<u8> {
    use std::fmt::Write;
    let mut s = String::from("solid bench\n");
    for f in &m.faces {
        s.push_str("facet normal 0 0 1\nouter loop\n");
        for &i in f {
            let p = m.vertices[i as usize];
            let _ = writeln!(s, "vertex {} {} {}", p[0] as f32, p[1] as f32, p[2] as f32);
        }
        s.push_str("endloop\nendfacet\n");
    }
    s.push_str("endsolid bench\n");
    s.into_bytes()
}

fn array_bytes(r: &RawShape) -> usize {
    r.vertices.len() * 24
        + r.polygons.indices.len() * 4
        + r.polygons.offsets.len() * 8
        + r.tets.len() * 16
        + r.segments.len() * 8
}

fn vm_hwm_kib() -> usize {
    let s = std::fs::read_to_string("/proc/self/status").unwrap_or_default();
    s.lines()
        .find(|l| l.starts_with("VmHWM:"))
        .and_then(|l| l.split_whitespace().nth(1))
        .and_then(|v| v.parse().ok())
        .unwrap_or(0)
}

fn main() {
    let args: Vec<String> = std::env::args().collect();
    if let Some(pos) = args.iter().position(|a| a == "--measure") {
        // Child: read the file, then parse once and report the peak growth and the final array bytes.
        let path = &args[pos + 1];
        let format = Format::from_name(&args[pos + 2]).unwrap();
        let bytes = std::fs::read(path).unwrap();
        let before = vm_hwm_kib();
        let raw = io::read_bytes(&bytes, format, &ReadOptions::default()).unwrap();
        let after = vm_hwm_kib();
        println!("{} {}", (after - before) * 1024, array_bytes(&raw));
        return;
    }
    if args.iter().any(|a| a == "--list" || a == "--test") {
        return; // cargo's harness probing
    }
    let m = mesh();
    let shape = kac_core::Shape::TriangleMesh(m.clone());
    let dir = std::env::temp_dir().join(format!("kac-parse-bench-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let cases: Vec<(&str, Format, Vec<u8>)> = vec![
        ("binary PLY (float32)", Format::Ply, ply_f32(&m)),
        ("binary PLY (float64)", Format::Ply, io::write::ply(&shape, true, None)),
        ("OBJ (17-digit coordinates)", Format::Obj, io::write::obj(&shape).into_bytes()),
        ("ASCII STL (float32 text)", Format::Stl, stl_ascii(&m)),
    ];
    println!("| input ({} triangles, {} vertices) | bytes | parse median | parse + validate median | peak growth / final arrays |", m.faces.len(), m.vertices.len());
    println!("|---|---|---|---|---|");
    let exe = std::env::current_exe().unwrap();
    for (name, format, bytes) in cases {
        let mut parse = Vec::new();
        let mut full = Vec::new();
        for _ in 0..5 {
            let t = Instant::now();
            let raw = io::read_bytes(&bytes, format, &ReadOptions::default()).unwrap();
            parse.push(t.elapsed().as_secs_f64());
            let t = Instant::now();
            let v = kac_core::validate(raw, &kac_core::ValidateOptions::default()).unwrap();
            full.push(parse.last().unwrap() + t.elapsed().as_secs_f64());
            assert_eq!(v.shape.vertex_count(), m.vertices.len());
        }
        parse.sort_by(f64::total_cmp);
        full.sort_by(f64::total_cmp);
        let path = dir.join(format!("mesh.{}", format.name()));
        std::fs::write(&path, &bytes).unwrap();
        let out = std::process::Command::new(&exe)
            .args(["--measure", path.to_str().unwrap(), format.name()])
            .output()
            .unwrap();
        let text = String::from_utf8_lossy(&out.stdout);
        let nums: Vec<f64> = text.split_whitespace().filter_map(|x| x.parse().ok()).collect();
        let ratio = if nums.len() == 2 && nums[1] > 0.0 {
            format!("{:.0} MB / {:.0} MB = {:.2}×", nums[0] / 1e6, nums[1] / 1e6, nums[0] / nums[1])
        } else {
            "n/a".into()
        };
        println!("| {name} | {:.1} MB | {:.3} s | {:.3} s | {ratio} |", bytes.len() as f64 / 1e6, parse[2], full[2]);
    }
    let _ = std::fs::remove_dir_all(&dir);
}
