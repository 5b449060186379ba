"""Fixtures of the Python package's tests: the kac binary (for the CLI's numbers and a real server), meshes it
generates with known spectra, and the shared meshes (KAC_TEST_DATA, or KAC_DATA_DIR, or ../shared/data)."""

import json
import os
import pathlib
import subprocess

import pytest

ROOT = pathlib.Path(__file__).resolve().parents[2]


def kac_bin() -> str:
    for candidate in (os.environ.get("KAC_BIN"), ROOT / "target/release/kac", ROOT / "target/debug/kac"):
        if candidate and pathlib.Path(candidate).is_file():
            return str(candidate)
    pytest.fail("no kac binary: build it (cargo build) or set KAC_BIN")


def run_cli(*args: str) -> dict:
    out = subprocess.run([kac_bin(), *args], check=True, capture_output=True, text=True)
    return json.loads(out.stdout)


@pytest.fixture(scope="session")
def meshes(tmp_path_factory):
    d = tmp_path_factory.mktemp("meshes")
    made = {}
    for name, args in {
        "sphere": ["icosphere", "--level", "3"],
        "torus": ["torus"],
        "disk": ["disk", "--n", "12"],
        "cube": ["cube-tets", "--n", "6"],
        "path": ["path", "--n", "12"],
    }.items():
        ext = ".json" if name in ("cube", "path") else ".off"
        path = d / f"{name}{ext}"
        subprocess.run([kac_bin(), "generate", *args, "--out", str(path)], check=True, capture_output=True)
        made[name] = str(path)
    return made


def shared_data() -> pathlib.Path:
    for var in ("KAC_TEST_DATA", "KAC_DATA_DIR"):
        if os.environ.get(var):
            return pathlib.Path(os.environ[var])
    return ROOT.parent / "shared" / "data"
