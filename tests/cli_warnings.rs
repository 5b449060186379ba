//! Every CLI subcommand prints each warning of its answer on stderr (`kac: warning CODE: message`), where a person
//! at a terminal sees it, besides the answer's `warnings` on stdout: one place prints them for every subcommand.

use std::process::{Command, Output};

fn kac() -> Command {
    Command::new(env!("CARGO_BIN_EXE_kac"))
}

/// The answer's warning codes, after checking that each is printed on stderr.
fn warned(out: &Output) -> Vec<String> {
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(out.status.success(), "{stderr}");
    let v: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    let codes: Vec<String> = v["warnings"]
        .as_array()
        .expect("every answer has warnings")
        .iter()
        .map(|w| w["code"].as_str().unwrap().to_string())
        .collect();
    for w in v["warnings"].as_array().unwrap() {
        let line = format!("kac: warning {}: {}", w["code"].as_str().unwrap(), w["message"].as_str().unwrap());
        assert!(stderr.lines().any(|l| l == line), "{line:?} is printed on stderr: {stderr}");
    }
    codes
}

/// 800 points on the unit sphere as XYZ (a golden-angle spiral).
fn sphere_cloud(dir: &std::path::Path) -> std::path::PathBuf {
    let n = 800;
    let mut s = String::new();
    for i in 0..n {
        let z = 1.0 - 2.0 * (i as f64 + 0.5) / n as f64;
        let r = (1.0 - z * z).sqrt();
        let phi = i as f64 * std::f64::consts::PI * (3.0 - 5f64.sqrt());
        s += &format!("{} {} {}\n", r * phi.cos(), r * phi.sin(), z);
    }
    let p = dir.join("cloud.xyz");
    std::fs::write(&p, s).unwrap();
    p
}

/// A cloud with the chapter's normalization warns `cloud-normalization-chapter` in every subcommand that builds its
/// operator, `spectrum` and `operator` included (which put it in their JSON only before).
#[test]
fn every_subcommand_on_a_cloud_prints_its_warnings() {
    let dir = tempfile::tempdir().unwrap();
    let cloud = sphere_cloud(dir.path());
    let runs: [&[&str]; 7] = [
        &["spectrum", "-k", "8", "--threads", "1"],
        &["operator"],
        &["hks", "-k", "8", "--threads", "1"],
        &["wks", "-k", "8", "--threads", "1"],
        &["shape-dna", "-k", "6", "--threads", "1"],
        &["heat", "-k", "8", "--threads", "1"],
        &["embed", "--threads", "1"],
    ];
    for args in runs {
        let out = kac().args(args).args(["--cloud-normalization", "chapter"]).arg(&cloud).output().unwrap();
        let codes = warned(&out);
        assert!(codes.iter().any(|c| c == "cloud-normalization-chapter"), "{args:?}: {codes:?}");
    }
}

/// A solve that gives up its plan (slices for one run) says so in `solver.plan` and warns `solver-fallback`.
#[test]
fn a_solver_fallback_is_reported_and_printed() {
    let dir = tempfile::tempdir().unwrap();
    // A thin strip, 300 × 0.5: its low spectrum grows like a segment's, so Weyl's law puts every pair asked for in
    // the first of four slices.
    let mesh = kac_core::geometry::generate::grid(1200, 2, 300.0, 0.5);
    let path = dir.path().join("strip.off");
    std::fs::write(&path, kac_core::io::write::off(&mesh)).unwrap();
    let out = kac()
        .args(["spectrum", "-k", "80", "--slices", "4", "--threads", "1", "--method", "sparse"])
        .arg(&path)
        .output()
        .unwrap();
    let codes = warned(&out);
    assert!(codes.iter().any(|c| c == "solver-fallback"), "{codes:?}");
    let v: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    assert_eq!(
        (v["solver"]["plan"]["planned"].as_str(), v["solver"]["plan"]["taken"].as_str()),
        (Some("slices"), Some("one-run"))
    );
    // The same solve asked in one run keeps its plan: no plan change, no warning.
    let out = kac().args(["spectrum", "-k", "80", "--threads", "1", "--method", "sparse"]).arg(&path).output().unwrap();
    assert!(!warned(&out).iter().any(|c| c == "solver-fallback"));
}
