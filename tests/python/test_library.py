"""kac in Python against the CLI on the same shapes (the same numbers: one engine, one request vocabulary), and
against closed forms where one is known; errors carry kac's stable codes."""

import numpy as np
import pytest

import kac
from conftest import run_cli


def close(a, b, rtol=1e-9, atol=1e-12):
    return np.allclose(np.asarray(a, dtype=float), np.asarray(b, dtype=float), rtol=rtol, atol=atol)


def cli_array(out, name):
    return np.array(out["arrays"][name]["values"], dtype=float)


def test_read_gives_numpy_geometry_and_the_report(meshes):
    s = kac.read(meshes["sphere"])
    assert s.kind == "triangle_mesh" and s.vertices.shape == (642, 3) and s.vertices.dtype == np.float64
    assert s.faces.shape == (1280, 3) and s.tets is None and s.edges is None
    assert isinstance(s.report, dict) and len(s.id) == 64
    assert np.array_equal(s.vertex_map, np.arange(642))
    t = kac.read(meshes["cube"])
    assert t.kind == "tet_mesh" and t.tets.shape[1] == 4


def test_spectrum_is_the_clis_and_the_spheres(meshes):
    s = kac.read(meshes["sphere"])
    values, vectors = kac.spectrum(s, k=16, threads=1)
    cli = run_cli("spectrum", meshes["sphere"], "--k", "16", "--threads", "1")
    assert close(values, cli["eigenvalues"], rtol=1e-10)
    # l(l+1) with multiplicity 2l+1, within the P1 error of 642 vertices.
    exact = np.repeat([0, 2, 6, 12], [1, 3, 5, 7])
    assert abs(values[0]) < 1e-9 and np.all(np.abs(values[1:] - exact[1:]) / exact[1:] < 0.03)
    L, M = kac.operator(s)
    assert vectors.shape == (642, 16)
    assert np.allclose(vectors.T @ (M @ vectors), np.eye(16), atol=1e-9)
    assert np.allclose(L @ vectors, (M @ vectors) * values, atol=1e-8)
    v2, _, report = kac.spectrum(s, k=4, report=True, mass="lumped")
    assert report["mass"] == "lumped" and report["completeness"]["complete"]


def test_operator_matches_the_clis_matrices(meshes, tmp_path):
    import scipy.io

    s = kac.read(meshes["torus"])
    for mass in ("consistent", "lumped"):
        L, M = kac.operator(s, mass=mass)
        out = tmp_path / mass
        run_cli("operator", meshes["torus"], "--mass", mass, "--out-dir", str(out))
        L_cli, M_cli = (scipy.io.mmread(str(out / f"{m}.mtx")).tocsr() for m in ("L", "M"))
        assert L.shape == L_cli.shape == (len(s.vertices),) * 2
        assert abs(L - L_cli).max() == 0 and abs(M - M_cli).max() == 0
        assert abs(L - L.T).max() == 0 and abs(L @ np.ones(L.shape[0])).max() < 1e-10
    # The lumped mass is diagonal, the consistent one is not; both sum to the area.
    assert kac.operator(s, mass="lumped")[1].nnz == len(s.vertices)
    assert np.isclose(kac.operator(s)[1].sum(), kac.operator(s, mass="lumped")[1].sum(), rtol=1e-12)


@pytest.mark.parametrize(
    "name, flags, options, array",
    [
        ("hks", ["--k", "30", "--count", "6"], dict(k=30, count=6), "hks"),
        ("wks", ["--k", "30"], dict(k=30), "wks"),
        ("heat", ["--k", "30", "--source", "3"], dict(k=30, sources=[3]), None),
        ("geodesic", ["--source", "0"], dict(sources=[0]), "distance"),
        ("embed", ["-d", "3"], dict(dimensions=3), None),
        ("mean-curvature", [], dict(), None),
    ],
)
def test_analyses_give_the_clis_numbers(meshes, name, flags, options, array):
    s = kac.read(meshes["sphere"])
    r = getattr(kac, name.replace("-", "_"))(s, threads=1, **options)
    cli = run_cli(name, meshes["sphere"], "--threads", "1", *flags) if name not in ("mean-curvature",) else run_cli(
        name, meshes["sphere"]
    )
    assert r["analysis"] == cli["analysis"] == name
    for key in ("k", "eigenvalues", "times", "energies", "heat_trace"):
        if key in cli:
            assert close(r[key], cli[key], rtol=1e-9), key
    names = [array] if array else list(cli.get("arrays", {}))
    assert names, cli.keys()
    for a in names:
        assert close(r.arrays[a], cli_array(cli, a), rtol=1e-8, atol=1e-10), a


def test_shape_dna_and_compare(meshes):
    s, t = kac.read(meshes["sphere"]), kac.read(meshes["torus"])
    r = kac.shape_dna(s, k=20, threads=1)
    cli = run_cli("shape-dna", meshes["sphere"], "--k", "20", "--threads", "1")
    assert close(r["shape_dna"]["values"], cli["shape_dna"]["values"], rtol=1e-9)
    c = kac.compare([s, t, s], k=20)
    d = np.array(c["distances"])
    assert d.shape == (3, 3) and d[0, 2] == 0 and d[0, 1] > 0 and np.allclose(d, d.T)


def test_correspondence_of_a_shape_with_itself_is_the_identity(meshes):
    s = kac.read(meshes["sphere"])
    r = kac.correspondence(s, s, fit_k=20, refine_k=40)
    m = r.arrays["source_to_target"]
    assert m.dtype == np.int64 and m.shape == (642,)
    assert (m == np.arange(642)).mean() > 0.95


def test_arrays_and_shapes_from_numpy():
    # A unit square of two triangles: its P1 Neumann spectrum starts at 0; the shape keeps the caller's rows.
    v = np.array([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0]], dtype=float)
    f = np.array([[0, 1, 2], [0, 2, 3]])
    values, vectors = kac.spectrum(v, f, k=3)
    assert abs(values[0]) < 1e-12 and vectors.shape == (4, 3)
    g = kac.shape(np.zeros((5, 3)), edges=[[0, 1], [1, 2], [2, 3], [3, 4]], graph=True)
    assert g.kind == "graph"
    # The path graph P5's Laplacian eigenvalues are 2 − 2 cos(πj/5).
    vals, _ = kac.spectrum(g, k=5)
    assert np.allclose(vals, 2 - 2 * np.cos(np.pi * np.arange(5) / 5), atol=1e-10)


def test_errors_carry_codes():
    v = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0]], dtype=float)
    with pytest.raises(kac.KacError) as e:
        kac.shape(v, [[0, 1, 7]])
    assert e.value.code == "index-out-of-range" and "faces[0]" in e.value.detail
    with pytest.raises(kac.KacError) as e:
        kac.shape(np.array([[0, 0, np.nan]]))
    assert e.value.code == "non-finite-value"
    with pytest.raises(kac.KacError) as e:
        kac.hks(v, [[0, 1, 2]], cout=3)
    assert e.value.code == "invalid-request" and "count" in str(e.value)
    g = kac.shape(np.zeros((3, 3)), edges=[[0, 1], [1, 2]], graph=True)
    with pytest.raises(kac.KacError) as e:
        kac.mean_curvature(g)
    # A refusal says what does work: the analysis' row of the registry.
    assert e.value.code == "unsupported" and e.value.extra["supported"]["classes"] == ["triangle_mesh"]
    with pytest.raises(kac.KacError) as e:
        kac.spectrum(v, [[0, 1, 2]], k=0)
    assert e.value.code == "invalid-k"
    assert set(kac.codes()) >= {"invalid-request", "unsupported", "incomplete-spectrum"}


def test_every_analysis_of_the_registry_is_a_function():
    names = [a["name"] for a in kac.analyses()]
    assert len(names) > 20
    for n in names:
        f = getattr(kac, n.replace("-", "_"))
        assert callable(f) and f.__doc__


def test_the_analysis_functions_are_what_the_registry_writes():
    import pathlib
    import subprocess
    import sys

    tool = pathlib.Path(__file__).resolve().parents[2] / "crates/kac-python/tools/gen_analyses.py"
    assert subprocess.run([sys.executable, str(tool), "--check"]).returncode == 0, "run tools/gen_analyses.py"
