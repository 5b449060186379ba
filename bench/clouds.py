#!/usr/bin/env python3
"""Point clouds as scanners deliver them (issue 21, item 4): kac's point-cloud operator against robust-laplacian
(Sharp & Crane 2020, `robust_laplacian.point_cloud_laplacian`, with scipy's eigsh in shift-invert mode) in one run
on the same clouds, one thread each: uniform random samples of the unit sphere with radial Gaussian noise σ = 0,
0.02, 0.04 and with 1 % of the points replaced by uniform outliers in the bounding box, 100,000 points; k = 50
eigenpairs. Prints a markdown table: seconds (operator and eigenpairs, the whole process for kac), λ₂..₄ (exact 2)
and the total mass (4π = 12.566).
Usage: OMP_NUM_THREADS=1 target/contract-venv/bin/python bench/clouds.py [N]
"""
import json, math, os, random, subprocess, sys, tempfile, time

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from kac_http import release_kac  # noqa: E402


def cloud(n, sigma, outliers, seed=1):
    rnd = random.Random(seed)
    pts = []
    for i in range(n):
        if outliers and i % 100 == 0:
            pts.append((rnd.uniform(-1, 1), rnd.uniform(-1, 1), rnd.uniform(-1, 1)))
            continue
        z = 2 * rnd.random() - 1
        p = 2 * math.pi * rnd.random()
        r = math.sqrt(1 - z * z)
        s = 1 + sigma * rnd.gauss(0, 1)
        pts.append((s * r * math.cos(p), s * r * math.sin(p), s * z))
    return pts


def main():
    n = int(sys.argv[1]) if len(sys.argv) > 1 else 100_000
    kac = release_kac()
    import numpy as np
    import robust_laplacian
    import scipy.sparse.linalg as sla
    work = tempfile.mkdtemp()
    print("| cloud (%d points) | method | seconds | λ₂..₄ | ΣM |" % n)
    print("|---|---|---|---|---|")
    for sigma, out in [(0.0, False), (0.02, False), (0.04, False), (0.02, True)]:
        pts = cloud(n, sigma, out)
        name = "σ = %g%s" % (sigma, ", 1 % outliers" if out else "")
        path = os.path.join(work, "c.xyz")
        with open(path, "w") as f:
            f.writelines("%r %r %r\n" % p for p in pts)
        t = time.perf_counter()
        r = json.loads(subprocess.run([kac, "spectrum", path, "-k", "50", "--threads", "1"], check=True,
                                      capture_output=True, text=True).stdout)
        s = time.perf_counter() - t
        mass = r["parameters"].get("total_area")
        print("| %s | kac point-cloud | %.2f | %s | %.3f |" % (name, s, ", ".join("%.3f" % x for x in r["eigenvalues"][1:4]), mass))
        t = time.perf_counter()
        L, M = robust_laplacian.point_cloud_laplacian(np.array(pts))
        vals = np.sort(sla.eigsh(L, k=50, M=M, sigma=-0.01, which="LM", return_eigenvectors=False))
        s = time.perf_counter() - t
        print("| %s | robust-laplacian | %.2f | %s | %.3f |" % (name, s, ", ".join("%.3f" % x for x in vals[1:4]), M.sum()))
        sys.stdout.flush()


if __name__ == "__main__":
    main()
