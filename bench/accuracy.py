#!/usr/bin/env python3
"""Accuracy against work (issue 20, item 4): eigenvalue error against unknowns and seconds (one thread) for P1,
P2 and their Richardson extrapolations (`kac spectrum --extrapolate`, two refinements) on
- the unit disk, Dirichlet: the first three eigenvalues j₀₁², j₁₁², j₁₁² (zeros of Bessel functions; Abramowitz &
  Stegun table 9.5), meshed by `kac generate disk` (a polygon: its own eigenvalues differ from the disk's by O(h²));
- the L-shaped membrane of three unit squares, Dirichlet: λ₁ = 9.6397238440219410527 (Fox, Henrici & Moler 1967);
- the Gordon–Webb–Wolpert drums 1 and 2 (`kac generate gww1|gww2`, half the size of Driscoll's: eigenvalues 4×),
  Dirichlet: the first 25 of Driscoll 1997 (SIAM Review 39, pp. 1–17, table 3; λ₉ = 5π²/4 and λ₂₁ = 5π²/2 there in
  closed form);
and a P1 peer in the same run: lapy's Solver (cotan stiffness, consistent mass, ARPACK shift-invert with SuperLU) on
the same meshes.
Prints a markdown table. Needs a Python with numpy, scipy and lapy (e.g. target/contract-venv after
scripts/peers.sh and `pip install lapy`).
Usage: target/contract-venv/bin/python bench/accuracy.py
"""
import json, math, os, subprocess, sys, tempfile, time

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from kac_http import release_kac  # noqa: E402

J01, J11 = 2.404825557695773, 3.831705970207512
DISK = [J01 ** 2, J11 ** 2, J11 ** 2]
L1 = [9.6397238440219410527]
DRISCOLL = [2.53794399980, 3.65550971352, 5.17555935622, 6.53755744376, 7.24807786256, 9.20929499840,
            10.5969856913, 11.5413953956, 12.3370055014, 13.0536540557, 14.3138624643, 15.8713026200,
            16.9417516880, 17.6651184368, 18.9810673877, 20.8823950433, 21.2480051774, 22.2328517930,
            23.7112974848, 24.4792340693, 24.6740110027, 26.0802400997, 27.3040189211, 28.1751285815,
            29.5697729132]
GWW = [4 * x for x in DRISCOLL]


def l_shape(n, path):
    """[−1, 1]² without [0, 1] × [−1, 0], n × n squares per unit, each cut along a diagonal."""
    m = 2 * n
    idx = lambda i, j: j * (m + 1) + i
    v = [(-1 + 2 * i / m, -1 + 2 * j / m) for j in range(m + 1) for i in range(m + 1)]
    f = []
    for j in range(m):
        for i in range(m):
            if i >= n and j < n:
                continue
            a, b, c, d = idx(i, j), idx(i + 1, j), idx(i + 1, j + 1), idx(i, j + 1)
            f += [(a, b, c), (a, c, d)] if (i + j) % 2 == 0 else [(a, b, d), (b, c, d)]
    used = sorted({x for t in f for x in t})
    new = {o: k for k, o in enumerate(used)}
    with open(path, "w") as out:
        out.write("OFF\n%d %d 0\n" % (len(used), len(f)))
        out.writelines("%r %r 0\n" % v[o] for o in used)
        out.writelines("3 %d %d %d\n" % tuple(new[x] for x in t) for t in f)


def kac_run(kac, path, k, order, extrapolate, refinements=2):
    """extrapolate: None, "uniform" or "graded" (toward re-entrant corners, kac's default)."""
    args = [kac, "spectrum", path, "-k", str(k), "--boundary", "dirichlet", "--order", str(order), "--threads", "1"]
    if extrapolate:
        args += ["--extrapolate", "--refinements", str(refinements)]
    if extrapolate == "uniform":
        args.append("--no-grading")
    t = time.perf_counter()
    r = json.loads(subprocess.run(args, check=True, capture_output=True, text=True).stdout)
    seconds = time.perf_counter() - t
    if extrapolate:
        e = r["extrapolation"]
        return e["eigenvalues"], e["levels"][-1]["unknowns"], seconds, max(e["error_estimate"])
    return r["eigenvalues"], r["size"], seconds, None


def lapy_run(path, k):
    import numpy as np
    import lapy
    words = open(path).read().split()
    nv, nf = int(words[1]), int(words[2])
    v = np.array(words[4:4 + 3 * nv], dtype=float).reshape(nv, 3)
    f = np.array(words[4 + 3 * nv:4 + 3 * nv + 4 * nf], dtype=np.int64).reshape(nf, 4)[:, 1:]
    t = time.perf_counter()
    tria = lapy.TriaMesh(v, f)
    inner = np.setdiff1d(np.arange(nv), tria.boundary_loops()[0] if len(tria.boundary_loops()) == 1 else np.concatenate(tria.boundary_loops()))
    solver = lapy.Solver(tria, lump=False)
    import scipy.sparse.linalg as sla
    a = solver.stiffness.tocsc()[inner][:, inner]
    b = solver.mass.tocsc()[inner][:, inner]
    vals = sla.eigsh(a, k=k, M=b, sigma=-0.01, which="LM", return_eigenvectors=False)
    return sorted(vals), len(inner), time.perf_counter() - t


def rel(got, exact):
    return max(abs(g - e) / e for g, e in zip(got, exact))


def main():
    kac = release_kac()
    work = tempfile.mkdtemp()
    cases = []
    for rings in (8, 16, 32):
        p = os.path.join(work, "disk%d.off" % rings)
        subprocess.run([kac, "generate", "disk", "--n", str(rings), "--out", p], check=True, stdout=subprocess.DEVNULL)
        cases.append(("disk, %d rings" % rings, p, DISK, 2))
    for n in (4, 8, 16):
        p = os.path.join(work, "l%d.off" % n)
        l_shape(n, p)
        cases.append(("L-shape, h = 1/%d" % n, p, L1, 2))
    for drum, n, refinements in ((1, 4, 2), (1, 4, 3), (2, 4, 3), (1, 8, 2), (1, 8, 3)):
        p = os.path.join(work, "gww%d-%d.off" % (drum, n))
        subprocess.run([kac, "generate", "gww%d" % drum, "--n", str(n), "--out", p], check=True,
                       stdout=subprocess.DEVNULL)
        cases.append(("GWW %d, h = 1/%d, %d refinements" % (drum, 2 * n, refinements), p, GWW, refinements))
    # P1 at the unknowns of the graded P2 extrapolation's finest level (28,289): the same cost, no extrapolation.
    p = os.path.join(work, "gww1-64.off")
    subprocess.run([kac, "generate", "gww1", "--n", "64", "--out", p], check=True, stdout=subprocess.DEVNULL)
    cases.append(("GWW 1, h = 1/128, P1 only", p, GWW, 0))
    print("| domain | method | unknowns (finest) | seconds | max rel. error | kac's estimate |")
    print("|---|---|---|---|---|---|")
    for name, path, exact, refinements in cases:
        k = len(exact)
        try:
            vals, n, s = lapy_run(path, k)
            print("| %s | lapy P1 (peer) | %d | %.3f | %.2e | |" % (name, n, s, rel(vals, exact)))
        except Exception as e:  # noqa: BLE001 — the peer is optional; say why it is missing
            print("| %s | lapy P1 (peer) | – | – | not run: %s | |" % (name, type(e).__name__))
        for order in (1, 2):
            for extrapolate in (None, "uniform", "graded") if refinements else (None,) if order == 1 else ():
                try:
                    vals, n, s, est = kac_run(kac, path, k, order, extrapolate, refinements)
                except subprocess.CalledProcessError as e:
                    print("| %s | kac P%d%s | – | – | not run: %s | |" % (
                        name, order, " extrapolated, %s" % extrapolate if extrapolate else "",
                        e.stderr.strip().splitlines()[-1]))
                    continue
                label = "kac P%d%s" % (order, " extrapolated, %s" % extrapolate if extrapolate else "")
                scale = max(exact)
                print("| %s | %s | %d | %.3f | %.2e | %s |" % (name, label, n, s, rel(vals, exact),
                                                             "%.1e" % (est / scale) if est is not None else ""))
        sys.stdout.flush()


if __name__ == "__main__":
    main()
