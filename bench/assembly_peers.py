"""Assembly time of the cotangent stiffness and mass matrices by the peers, on the OFF files kac wrote.

Prints one JSON line per (mesh, peer). Medians of 7 runs after a warm-up, single-threaded (OPENBLAS_NUM_THREADS=1
is set by bench/assembly.sh). Peers: libigl (cotmatrix + barycentric massmatrix), lapy (Solver(lump=False),
which assembles the stiffness and consistent mass), robust-laplacian (mesh_laplacian: tufted iDT, lumped mass).
"""
import json
import statistics
import sys
import time

import numpy as np


def read_off(path):
    with open(path) as f:
        words = f.read().split()
    assert words[0] == "OFF"
    nv, nf = int(words[1]), int(words[2])
    v = np.array(words[4:4 + 3 * nv], dtype=np.float64).reshape(nv, 3)
    f = np.array(words[4 + 3 * nv:4 + 3 * nv + 4 * nf], dtype=np.int64).reshape(nf, 4)[:, 1:]
    return v, f


def timed(fn, runs=7):
    fn()
    out = []
    for _ in range(runs):
        t = time.perf_counter()
        fn()
        out.append(time.perf_counter() - t)
    return statistics.median(out)


def main():
    import igl
    import lapy
    import robust_laplacian

    for path in sys.argv[1:]:
        v, f = read_off(path)
        fi = f.astype(np.int32)

        def run_igl():
            igl.cotmatrix(v, fi)
            igl.massmatrix(v, fi, igl.MASSMATRIX_TYPE_BARYCENTRIC)

        def run_lapy():
            lapy.Solver(lapy.TriaMesh(v, f), lump=False)

        def run_robust():
            robust_laplacian.mesh_laplacian(v, f)

        for name, fn in [("libigl", run_igl), ("lapy", run_lapy), ("robust-laplacian", run_robust)]:
            print(json.dumps({"vertices": len(v), "peer": name, "median_s": timed(fn)}), flush=True)


if __name__ == "__main__":
    main()
