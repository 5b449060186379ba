"""kac.Client against a real `kac serve` on loopback: upload, a job waited for with progress, the result's arrays
as NumPy (the same numbers as the library in process), bulk upload, search, compare, correspondence, problems as
KacError with their codes."""

import json
import subprocess

import numpy as np
import pytest

import kac
from conftest import kac_bin


@pytest.fixture(scope="module")
def server(tmp_path_factory):
    data = tmp_path_factory.mktemp("store")
    p = subprocess.Popen(
        [kac_bin(), "serve", "--addr", "127.0.0.1:0", "--data-dir", str(data), "--workers", "2"],
        stdout=subprocess.PIPE,
        stderr=subprocess.DEVNULL,
        text=True,
    )
    line = p.stdout.readline()
    addr = json.loads(line)["listening"]
    yield f"http://{addr}"
    p.terminate()
    p.wait(timeout=30)


def test_the_walkthrough_through_the_client(server, meshes):
    c = kac.Client(server)
    shape = c.upload(meshes["sphere"])
    assert shape["summary"]["vertices"] == 642
    seen = []
    r = c.analyze(shape["id"], "spectrum", k=10, eigenvectors=True, progress=lambda *p: seen.append(p))
    local, vectors = kac.spectrum(kac.read(meshes["sphere"]), k=10)
    assert np.allclose(r["eigenvalues"], local, rtol=1e-9, atol=1e-12)
    phi = r["arrays"]["eigenvectors"]
    assert isinstance(phi, np.ndarray) and phi.shape == (642, 10)
    # Repeated eigenvalues (the sphere's 3 and 5) have many bases: the eigenpairs are checked, not the basis.
    L, M = kac.operator(kac.read(meshes["sphere"]))
    assert np.allclose(phi.T @ (M @ phi), np.eye(10), atol=1e-8)
    assert np.allclose(L @ phi, (M @ phi) * local, atol=1e-7)
    assert all(len(p) == 3 for p in seen)


def test_bulk_search_compare_and_correspondence(server, meshes):
    c = kac.Client(server)
    bulk = c.upload_bulk([meshes["sphere"], meshes["torus"], meshes["disk"]])
    ids = [f["shape"]["id"] for f in bulk["files"]]
    assert len(ids) == 3
    for f in bulk["files"]:
        if f.get("job"):
            c.wait(f["job"])
    found = c.search(shape_id=ids[0], neighbours=2)
    assert found["searched"] >= 2 and len(found["neighbours"]) == 2
    cmp = c.compare(ids[:2], k=20, descriptor="shape-dna")
    d = np.array(cmp["distances"])
    assert d.shape == (2, 2) and d[0, 0] == 0 and d[0, 1] > 0
    corr = c.correspondence(ids[0], ids[0], fit_k=20, refine_k=30)
    m = corr["arrays"]["source_to_target"]
    assert m.shape[0] == 642 and (m[:, 0] == np.arange(642)).mean() > 0.95


def test_problems_are_kac_errors_with_codes(server):
    c = kac.Client(server)
    with pytest.raises(kac.KacError) as e:
        c.shape("0" * 64)
    assert e.value.code == "not-found" and e.value.status == 404
    with pytest.raises(kac.KacError) as e:
        c.submit("0" * 64, "hks", cout=3)
    # The body is checked before the shape is looked up: the unknown field, named.
    assert e.value.code == "invalid-request" and e.value.status == 422 and e.value.extra["field"] == "cout"
