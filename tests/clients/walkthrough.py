"""The README walkthrough through the Python client generated from openapi/openapi.json by openapi-python-client
(scripts/clients.sh generates it, starts a real server on loopback and runs this): upload a shape, run a spectrum
job, read the typed result, fetch an array as .npy, fingerprint two shapes and search. Exits non-zero on any
mismatch."""

import io
import math
import sys
import time

import numpy as np
from kac_client import Client
from kac_client.api.jobs import create_job, get_job, list_analyses, search
from kac_client.api.results import get_result
from kac_client.api.shapes import upload_shape
from kac_client.models import (
    AnalysesTable,
    Format,
    JobResource,
    SearchRequest,
    SearchResult,
    FingerprintAnalysisAnalysis,
    FingerprintJobRequest,
    FingerprintOptions,
    ShapeResource,
    SpectrumAnalysisAnalysis,
    SpectrumJobRequest,
    SpectrumResult,
)
from kac_client.types import File


def check(condition, what):
    if not condition:
        print(f"walkthrough: {what}", file=sys.stderr)
        sys.exit(1)


def finished(client, job):
    """Polls a job until it ends; returns the final JobResource."""
    deadline = time.time() + 120
    while job.status.value not in ("succeeded", "failed", "canceled"):
        check(time.time() < deadline, f"job {job.id} still {job.status.value} after 120 s")
        time.sleep(0.2)
        job = get_job.sync(client=client, id=job.id)
        check(isinstance(job, JobResource), f"GET /v1/jobs/{{id}} gave {job!r}")
    check(job.status.value == "succeeded", f"job {job.id} ended {job.status.value}: {job.error}")
    return job


def upload(client, path):
    with open(path, "rb") as f:
        body = File(payload=io.BytesIO(f.read()), file_name=path)
    shape = upload_shape.sync(client=client, body=body, format_=Format.OFF)
    check(isinstance(shape, ShapeResource), f"upload gave {shape!r}")
    return shape


def main(base, sphere, torus):
    client = Client(base_url=base, timeout=120)
    # 1. Upload: a typed shape resource with its validation summary.
    shape = upload(client, sphere)
    check(shape.summary.vertices == 642 and shape.summary.closed, f"summary: {shape.summary}")
    # The truth table says what applies to it.
    table = list_analyses.sync(client=client, shape_id=shape.id)
    check(isinstance(table, AnalysesTable) and table.class_ is not None, f"table: {table!r}")
    check(all(a.applies for a in table.analyses), "every analysis applies to a triangle mesh")
    # 2. A spectrum job with its eigenvectors.
    req = SpectrumJobRequest(analysis=SpectrumAnalysisAnalysis.SPECTRUM, shape_id=shape.id, k=10, eigenvectors=True)
    job = finished(client, create_job.sync(client=client, body=req))
    # 3. The typed result: the unit sphere's spectrum 0, 2, 2, 2, 6, … (P1 on 642 vertices: within 3 %).
    # The union of results is resolved by `analysis`: a spectrum job's result is a SpectrumResult, every field typed.
    result = get_result.sync(client=client, id=job.id)
    check(isinstance(result, SpectrumResult), f"result: {result!r}")
    check(result.analysis.value == "spectrum" and result.shape_id == shape.id, f"result: {result.analysis}")
    check(result.warnings == [], f"warnings: {result.warnings}")
    check(result.completeness.complete and result.solver.zero_modes == 1, f"solver: {result.solver}")
    values = result.eigenvalues
    exact = [0, 2, 2, 2, 6, 6, 6, 6, 6, 12]
    check(all(abs(v - e) <= 0.03 * max(e, 1) for v, e in zip(values, exact)), f"eigenvalues {values}")
    # 4. An array as .npy: 642 rows, one column per eigenpair, M-orthonormal columns' signs fixed.
    links = result.arrays.additional_properties["eigenvectors"]
    check(links.rows == 642 and links.cols == 10, f"array: {links}")
    # Followed from the result's link with the client's connection: the generated get_array parses every 200 as
    # JSON (openapi-python-client reads one media type per response; an array is .npy, .json, .ply, …).
    raw = client.get_httpx_client().get(links.npy)
    check(raw.status_code == 200, f"GET {links.npy}: {raw.status_code}")
    phi = np.load(io.BytesIO(raw.content))
    check(phi.shape == (642, 10) and np.isfinite(phi).all(), f".npy shape {phi.shape}")
    check(abs(np.std(phi[:, 0]) * math.sqrt(642)) < 1e-6, "the first eigenvector is constant")
    # 5. The retrieval fingerprints of two shapes, then search by the sphere (fused over every family).
    other = upload(client, torus)
    for s in (shape, other):
        fp = FingerprintJobRequest(
            analysis=FingerprintAnalysisAnalysis.FINGERPRINT, shape_id=s.id, options=FingerprintOptions(k=20)
        )
        finished(client, create_job.sync(client=client, body=fp))
    found = search.sync(client=client, body=SearchRequest(shape_id=shape.id, k=20, neighbours=5))
    check(isinstance(found, SearchResult), f"search: {found!r}")
    check(found.searched == 2 and [n.shape_id for n in found.neighbours] == [other.id], f"search: {found}")
    print("walkthrough: ok")


if __name__ == "__main__":
    main(*sys.argv[1:4])
