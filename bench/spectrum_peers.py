"""Eigensolver peers on the same icospheres and the same operator as kac (P1 FEM, consistent mass):
scipy eigsh (ARPACK) in shift-invert mode with SuperLU (as lapy and pyFM do) or with CHOLMOD (scikit-sparse 0.4.16,
Debian's libsuitesparse-dev) as the inverse, and lapy's own Solver.eigs with SuperLU or with cholespy
(`use_cholmod=True`).
Reads each OFF file and the matching kac result (JSON from `kac spectrum`), checks that eigenvalues agree to 1e-8
relative, prints one JSON line per (mesh, k, peer) with time and peak memory (ru_maxrss of a fresh process).
Usage: spectrum_peers.py PEER OFF K KAC_JSON  (one measurement per process, so peak memory is its own).
"""
import json
import resource
import sys
import time

import numpy as np


def read_off(path):
    with open(path) as f:
        words = f.read().split()
    nv, nf = int(words[1]), int(words[2])
    v = np.array(words[4:4 + 3 * nv], dtype=np.float64).reshape(nv, 3)
    f = np.array(words[4 + 3 * nv:4 + 3 * nv + 4 * nf], dtype=np.int64).reshape(nf, 4)[:, 1:]
    return v, f


def main():
    peer, path, k, kac_json = sys.argv[1], sys.argv[2], int(sys.argv[3]), sys.argv[4]
    import lapy
    import scipy.sparse.linalg as sla

    v, f = read_off(path)
    t0 = time.perf_counter()
    if peer == "scipy-superlu":
        solver = lapy.Solver(lapy.TriaMesh(v, f), lump=False)
        a, b = solver.stiffness.tocsc(), solver.mass.tocsc()
        vals, _ = sla.eigsh(a, k=k, M=b, sigma=-0.01, which="LM")
    elif peer == "scipy-cholmod":
        from sksparse.cholmod import cholesky

        solver = lapy.Solver(lapy.TriaMesh(v, f), lump=False)
        a, b = solver.stiffness.tocsc(), solver.mass.tocsc()
        sigma = -0.01
        factor = cholesky((a - sigma * b).tocsc())
        opinv = sla.LinearOperator(a.shape, matvec=factor.solve_A, dtype=np.float64)
        vals, _ = sla.eigsh(a, k=k, M=b, sigma=sigma, which="LM", OPinv=opinv)
    elif peer == "lapy":
        solver = lapy.Solver(lapy.TriaMesh(v, f), lump=False)
        vals, _ = solver.eigs(k=k)
    elif peer == "lapy-cholespy":
        solver = lapy.Solver(lapy.TriaMesh(v, f), lump=False, use_cholmod=True)
        vals, _ = solver.eigs(k=k)
    else:
        raise SystemExit(f"unknown peer {peer}")
    elapsed = time.perf_counter() - t0
    vals = np.sort(vals)
    kac = np.array(json.load(open(kac_json))["eigenvalues"])
    scale = np.maximum(np.abs(kac), 1.0)
    agree = float(np.max(np.abs(vals - kac) / scale))
    peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss * 1024
    print(json.dumps({"vertices": len(v), "k": k, "peer": peer, "seconds": elapsed, "peak_bytes": peak, "max_rel_diff_vs_kac": agree}), flush=True)
    if not agree <= 1e-8:
        raise SystemExit(f"{peer}: eigenvalues differ from kac's by {agree:.2e} relative (more than 1e-8) on {path}")


if __name__ == "__main__":
    main()
