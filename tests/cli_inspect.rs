//! `kac inspect` as a user runs it: one JSON object on stdout and exit 0 for readable input; exit 2 and one
//! line on stderr for unreadable input; never a panic.

use std::path::PathBuf;
use std::process::Command;

fn kac() -> Command {
    Command::new(env!("CARGO_BIN_EXE_kac"))
}

/// A shared mesh; a test that needs one is #[ignore]d (run by scripts/test-all.sh where the data is) and fails,
/// never skips silently, when it cannot be found.
fn data(rel: &str) -> PathBuf {
    let dir = std::env::var_os("KAC_TEST_DATA")
        .or_else(|| std::env::var_os("KAC_DATA_DIR"))
        .map(PathBuf::from)
        .unwrap_or_else(|| PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../shared/data"));
    let p = dir.join(rel);
    assert!(p.is_file(), "shared test data not found at {} (set KAC_TEST_DATA)", p.display());
    p
}

#[test]
#[ignore = "needs the shared meshes (KAC_TEST_DATA or ../shared/data): scripts/test-all.sh runs it with --ignored where they are"]
fn inspect_prints_the_summary_contract() {
    let file = data("obj/torus.obj");
    let out = kac().arg("inspect").arg(&file).output().unwrap();
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let v: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    for key in [
        "kind",
        "vertices",
        "elements",
        "id",
        "bbox",
        "area",
        "volume",
        "components",
        "boundary_loops",
        "manifold",
        "orientation",
        "genus",
        "warnings",
        "report",
        "format",
    ] {
        assert!(v.get(key).is_some(), "missing {key}");
    }
    assert_eq!(v["kind"], "triangle_mesh");
    assert_eq!(v["vertices"], 2304);
    assert_eq!(v["genus"], 1);
    assert_eq!(v["id"].as_str().unwrap().len(), 64);
}

#[test]
fn explicit_format_overrides_the_extension() {
    let dir = tempfile::tempdir().unwrap();
    let p = dir.path().join("shape.dat");
    std::fs::write(&p, "OFF\n3 1 0\n0 0 0\n1 0 0\n0 1 0\n3 0 1 2\n").unwrap();
    let out = kac().args(["inspect", "--format", "off"]).arg(&p).output().unwrap();
    assert!(out.status.success());
    // And sniffing finds it without the flag.
    let out = kac().arg("inspect").arg(&p).output().unwrap();
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
}

#[test]
fn unreadable_input_exits_2_with_one_line() {
    let dir = tempfile::tempdir().unwrap();
    let cases: [(&str, &[u8]); 4] = [
        ("bad.obj", b"v 0 0 0\nf 1 2 3\n"),
        ("nan.off", b"OFF\n1 0 0\nnan 0 0\n"),
        ("garbage.bin", &[0xff, 0x00, 0x13, 0x37, 0x42]),
        ("trunc.ply", b"ply\nformat binary_little_endian 1.0\nelement vertex 10\nproperty float x\nproperty float y\nproperty float z\nend_header\n\x00\x00"),
    ];
    for (name, bytes) in cases {
        let p = dir.path().join(name);
        std::fs::write(&p, bytes).unwrap();
        let out = kac().arg("inspect").arg(&p).output().unwrap();
        assert_eq!(out.status.code(), Some(2), "{name}");
        let err = String::from_utf8_lossy(&out.stderr);
        assert_eq!(err.trim_end().lines().count(), 1, "{name}: {err}");
        assert!(err.starts_with("kac: ") && !err.contains("panicked"), "{name}: {err}");
        assert!(out.stdout.is_empty());
    }
    let out = kac().args(["inspect", "/definitely/not/here.obj"]).output().unwrap();
    assert_eq!(out.status.code(), Some(2));
}
