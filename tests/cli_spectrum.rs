//! `kac operator` and `kac spectrum` as users run them: the JSON contracts, Matrix Market and .npy output.

use std::process::Command;

fn kac() -> Command {
    Command::new(env!("CARGO_BIN_EXE_kac"))
}

fn write_square(dir: &std::path::Path, n: usize) -> std::path::PathBuf {
    // A grid of the unit square as OFF, with one unreferenced vertex at the end to exercise the vertex map.
    let mut s = format!("OFF\n{} {} 0\n", (n + 1) * (n + 1) + 1, 2 * n * n);
    for j in 0..=n {
        for i in 0..=n {
            s += &format!("{} {} 0\n", i as f64 / n as f64, j as f64 / n as f64);
        }
    }
    s += "5 5 5\n";
    for j in 0..n {
        for i in 0..n {
            let a = j * (n + 1) + i;
            s += &format!("3 {} {} {}\n3 {} {} {}\n", a, a + 1, a + n + 2, a, a + n + 2, a + n + 1);
        }
    }
    let p = dir.join("square.off");
    std::fs::write(&p, s).unwrap();
    p
}

#[test]
fn spectrum_json_and_eigenvectors_npy() {
    let dir = tempfile::tempdir().unwrap();
    let sq = write_square(dir.path(), 24);
    let npy = dir.path().join("phi.npy");
    let out = kac()
        .args(["spectrum", "-k", "4", "--boundary", "dirichlet", "--threads", "1", "--eigenvectors"])
        .arg(&npy)
        .arg(&sq)
        .output()
        .unwrap();
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let v: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    for key in ["eigenvalues", "residuals", "operator", "mass", "boundary", "timings", "solver", "shape_id"] {
        assert!(v.get(key).is_some(), "missing {key}");
    }
    assert_eq!(v["operator"], "cotan");
    assert_eq!(v["boundary"], "dirichlet");
    let ev: Vec<f64> = serde_json::from_value(v["eigenvalues"].clone()).unwrap();
    // Unit square, Dirichlet: 2π², 5π², 5π², 8π² (to discretization error).
    let pi2 = std::f64::consts::PI.powi(2);
    for (g, w) in ev.iter().zip([2.0, 5.0, 5.0, 8.0]) {
        assert!((g / (w * pi2) - 1.0).abs() < 0.02, "{g} vs {}", w * pi2);
    }
    // .npy: header, shape (input vertices, k); NaN for the unreferenced vertex, 0 on the boundary.
    let bytes = std::fs::read(&npy).unwrap();
    assert!(bytes.starts_with(b"\x93NUMPY\x01\x00"));
    let hlen = u16::from_le_bytes([bytes[8], bytes[9]]) as usize;
    let header = std::str::from_utf8(&bytes[10..10 + hlen]).unwrap();
    let rows = 25 * 25 + 1;
    assert!(header.contains(&format!("'shape': ({rows}, 4)")), "{header}");
    assert_eq!((10 + hlen) % 64, 0);
    let data: Vec<f64> =
        bytes[10 + hlen..].chunks_exact(8).map(|c| f64::from_le_bytes(c.try_into().unwrap())).collect();
    assert_eq!(data.len(), rows * 4);
    assert!(data[(rows - 1) * 4].is_nan());
    assert_eq!(data[0], 0.0, "corner vertex is on the Dirichlet boundary");
}

#[test]
fn operator_report_and_matrix_market() {
    let dir = tempfile::tempdir().unwrap();
    let sq = write_square(dir.path(), 6);
    let out_dir = dir.path().join("mats");
    let out =
        kac().args(["operator", "--report", "--mass", "lumped", "--out-dir"]).arg(&out_dir).arg(&sq).output().unwrap();
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let v: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    assert_eq!(v["size"], 49);
    assert_eq!(v["mass"], "lumped");
    let p = &v["properties"];
    assert_eq!(p["linear_precision"]["holds"], true, "flat mesh: cotan has linear precision");
    assert_eq!(p["symmetric"]["holds"], true);
    let l = std::fs::read_to_string(out_dir.join("L.mtx")).unwrap();
    assert!(l.starts_with("%%MatrixMarket matrix coordinate real symmetric"));
    let m = std::fs::read_to_string(out_dir.join("M.mtx")).unwrap();
    // Lumped mass: 49 diagonal entries summing to the area 1.
    let body: Vec<&str> = m.lines().filter(|l| !l.starts_with('%')).collect();
    assert_eq!(body[0], "49 49 49");
    let total: f64 = body[1..].iter().map(|l| l.split_whitespace().nth(2).unwrap().parse::<f64>().unwrap()).sum();
    assert!((total - 1.0).abs() < 1e-12);
    // SciPy's .npz beside each (read back in the router tests; by SciPy itself in scripts/peers.sh) and the
    // vertex of each unknown.
    assert!(std::fs::read(out_dir.join("L.npz")).unwrap().starts_with(b"PK\x03\x04"));
    assert_eq!(v["files"]["M_npz"], out_dir.join("M.npz").display().to_string());
    assert!(out_dir.join("unknown_vertices.npy").exists());
    let out = kac().args(["operator", "--boundary", "dirichlet", "--out-dir"]).arg(&out_dir).arg(&sq).output().unwrap();
    let d: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    assert_eq!(d["interior_vertices"].as_array().map(Vec::len), Some(25), "{d}");
    // A bad operator name or an operator that does not fit the shape: exit 2, one line.
    let out = kac().args(["operator", "--operator", "tet"]).arg(&sq).output().unwrap();
    assert_eq!(out.status.code(), Some(2));
    assert!(String::from_utf8_lossy(&out.stderr).contains("does not apply"));
    let out = kac().args(["spectrum", "-k", "0"]).arg(&sq).output().unwrap();
    assert_eq!(out.status.code(), Some(2));
    // Band mode: Dirichlet eigenvalues of the unit square in [10, 60] are 2π² and 5π² (×2).
    let out = kac().args(["spectrum", "--boundary", "dirichlet", "--band", "10,60"]).arg(&sq).output().unwrap();
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let v: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    assert_eq!(v["k"], 3, "{v}");
}

#[test]
fn completeness_is_checked_by_default_and_no_verify_turns_it_off() {
    let dir = tempfile::tempdir().unwrap();
    let sq = write_square(dir.path(), 24);
    let run = |extra: &[&str]| {
        let out = kac()
            .args(["spectrum", "-k", "4", "--boundary", "dirichlet", "--method", "sparse"])
            .args(extra)
            .arg(&sq)
            .output()
            .unwrap();
        assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
        serde_json::from_slice::<serde_json::Value>(&out.stdout).unwrap()
    };
    for v in [run(&[]), run(&["--verify"])] {
        let c = &v["solver"]["completeness"];
        // 2π², 5π², 5π², 8π², then 10π² (twice): τ falls in the first gap above λ₄ among the converged pairs,
        // between 8π² and 10π², with exactly four eigenvalues below it.
        assert_eq!(c["method"], "inertia", "{c}");
        assert_eq!(c["complete"], true, "{c}");
        assert_eq!(c["below_shift"], 4, "{c}");
        let pi2 = std::f64::consts::PI.powi(2);
        let shift = c["shift"].as_f64().unwrap();
        assert!(shift > 8.1 * pi2 && shift < 9.9 * pi2, "{shift}");
        assert_eq!(v["solver"]["zero_modes"], 0, "Dirichlet: no zero mode");
    }
    let v = run(&["--no-verify"]);
    assert!(v["solver"]["completeness"].is_null(), "{v}");
}

/// `--slices` as a user runs it: three slices of the Dirichlet square's 90 smallest pairs give the eigenvalues of one
/// run, `solver.slices` reports each window (tiling the spectrum, open at both ends), and the result still matches
/// the committed OpenAPI schema of a spectrum.
#[test]
fn spectrum_with_slices_reports_them_and_agrees_with_one_run() {
    let dir = tempfile::tempdir().unwrap();
    let sq = write_square(dir.path(), 40);
    let run = |slices: &str| -> serde_json::Value {
        let out = kac()
            .args(["spectrum", "-k", "90", "--boundary", "dirichlet", "--threads", "1", "--method", "sparse"])
            .args(["--slices", slices])
            .arg(&sq)
            .output()
            .unwrap();
        assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
        serde_json::from_slice(&out.stdout).unwrap()
    };
    let (one, three) = (run("1"), run("3"));
    assert!(one["solver"].get("slices").is_none(), "{}", one["solver"]);
    let slices = three["solver"]["slices"].as_array().unwrap();
    assert_eq!(slices.len(), 3, "{}", three["solver"]);
    assert!(slices[0]["lo"].is_null() && slices[2]["hi"].is_null());
    assert_eq!(slices[0]["hi"], slices[1]["lo"]);
    assert_eq!(slices[1]["hi"], slices[2]["lo"]);
    let pairs: u64 = slices.iter().map(|s| s["pairs"].as_u64().unwrap()).sum();
    assert!(pairs >= 90, "{pairs}");
    assert_eq!(three["completeness"]["complete"], true);
    let (a, b) = (one["eigenvalues"].as_array().unwrap(), three["eigenvalues"].as_array().unwrap());
    assert_eq!(a.len(), 90);
    for (x, y) in a.iter().zip(b) {
        let (x, y) = (x.as_f64().unwrap(), y.as_f64().unwrap());
        assert!((x - y).abs() <= 1e-10 * x.abs(), "{x} vs {y}");
    }
    let mut result = three.clone();
    result["result_id"] = serde_json::json!("0".repeat(64));
    schema::ResultSchemas::committed().check(&result).unwrap();
    // Out of range: refused before anything is computed, naming the setting.
    let out = kac().args(["spectrum", "-k", "90", "--slices", "0"]).arg(&sq).output().unwrap();
    assert!(!out.status.success());
    assert!(String::from_utf8_lossy(&out.stderr).contains("slices"), "{}", String::from_utf8_lossy(&out.stderr));
}

#[path = "support/schema.rs"]
mod schema;
