"""kac from Python against the Python peers, in one run, one thread, on the same meshes: the k smallest eigenpairs
of P1 FEM with consistent mass on unit icospheres.

- kac: ``kac.spectrum`` (the installed package, crates/kac-python), the shape read by ``kac.read`` (not timed);
- lapy: ``lapy.Solver(TriaMesh).eigs`` (SuperLU), assembly included;
- lapy+cholespy: ``lapy.Solver(..., use_cholmod=True).eigs``;
- scipy+CHOLMOD: ``scipy.sparse.linalg.eigsh`` in shift-invert mode with scikit-sparse's CHOLMOD factor of
  L − σM (σ = −0.01, lapy's), on kac's matrices (assembly not timed).

Also Ctrl-C: a solve of ``--interrupt LEVEL:K`` in a child process is sent SIGINT after 3 s; the time until the child
has raised KeyboardInterrupt is printed.

Usage (bench/.venv has the peers: bash bench/spectrum.sh installs them; then pip install ./crates/kac-python):

    OPENBLAS_NUM_THREADS=1 OMP_NUM_THREADS=1 bench/.venv/bin/python bench/python.py [--cases 5:50,6:200,7:200]
        [--interrupt 7:1000] [--skip-lu-above 50000]

Prints a Markdown table (seconds; ratios to kac) and writes raw rows to bench/out/python.jsonl.
"""

import argparse
import json
import os
import pathlib
import signal
import subprocess
import sys
import time

import numpy as np

import kac

ROOT = pathlib.Path(__file__).resolve().parents[1]
OUT = ROOT / "bench" / "out"


def mesh(level: int) -> str:
    OUT.mkdir(parents=True, exist_ok=True)
    f = OUT / f"ico{level}.off"
    if not f.exists():
        binary = ROOT / "target" / "release" / "kac"
        subprocess.run([str(binary), "generate", "icosphere", "--level", str(level), "--out", str(f)], check=True)
    return str(f)


def timed(f):
    t = time.perf_counter()
    out = f()
    return time.perf_counter() - t, out


def run_kac(path: str, k: int):
    s = kac.read(path)
    return timed(lambda: kac.spectrum(s, k=k, threads=1)[0])


def run_lapy(path: str, k: int, cholmod: bool):
    import lapy

    s = kac.read(path, weld="none")
    mesh_ = lapy.TriaMesh(s.vertices, s.faces)
    return timed(lambda: lapy.Solver(mesh_, use_cholmod=cholmod).eigs(k=k)[0])


def run_scipy_cholmod(path: str, k: int):
    from scipy.sparse.linalg import LinearOperator, eigsh
    from sksparse.cholmod import cholesky

    L, M = kac.operator(kac.read(path))
    L, M = L.tocsc(), M.tocsc()

    def solve():
        factor = cholesky(L + 0.01 * M)
        op = LinearOperator(L.shape, matvec=factor, dtype=np.float64)
        vals, _ = eigsh(L, k, M, sigma=-0.01, OPinv=op)
        return np.sort(vals)

    return timed(solve)


INTERRUPT = """
import sys, time, kac
s = kac.read(sys.argv[1])
print("solving", flush=True)
try:
    kac.spectrum(s, k=int(sys.argv[2]), threads=1)
    print("finished", flush=True)
except KeyboardInterrupt:
    print("interrupted", flush=True)
"""


def interrupt(level: int, k: int) -> dict:
    child = subprocess.Popen([sys.executable, "-c", INTERRUPT, mesh(level), str(k)], stdout=subprocess.PIPE, text=True)
    assert child.stdout.readline().strip() == "solving"
    time.sleep(3.0)
    sent = time.perf_counter()
    child.send_signal(signal.SIGINT)
    out, _ = child.communicate(timeout=120)
    return {"level": level, "k": k, "outcome": out.strip(), "seconds_after_sigint": time.perf_counter() - sent}


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--cases", default="5:50,6:200,7:200")
    ap.add_argument("--interrupt", default="7:1000")
    ap.add_argument("--skip-lu-above", type=int, default=50_000, help="lapy with SuperLU only below this size")
    a = ap.parse_args()
    rows = []
    with open(OUT / "python.jsonl" if OUT.exists() else os.devnull, "w") as raw:
        for case in a.cases.split(","):
            level, k = map(int, case.split(":"))
            path = mesh(level)
            n = len(kac.read(path).vertices)
            row = {"vertices": n, "k": k}
            t, ref = run_kac(path, k)
            row["kac"] = t
            peers = [("lapy+cholespy", lambda: run_lapy(path, k, True)), ("scipy+CHOLMOD", lambda: run_scipy_cholmod(path, k))]
            if n <= a.skip_lu_above:
                peers.insert(0, ("lapy", lambda: run_lapy(path, k, False)))
            for name, f in peers:
                try:
                    t, vals = f()
                except ImportError as e:
                    row[name] = None
                    print(f"{name}: not installed ({e})", file=sys.stderr)
                    continue
                row[name] = t
                diff = np.max(np.abs(vals[1:] - ref[1:]) / np.abs(ref[1:]))
                row[f"{name} max rel. diff"] = float(diff)
            rows.append(row)
            raw.write(json.dumps(row) + "\n")
            raw.flush()
        stop = interrupt(*map(int, a.interrupt.split(":"))) if a.interrupt else None
        if stop:
            raw.write(json.dumps({"interrupt": stop}) + "\n")
    names = ["lapy", "lapy+cholespy", "scipy+CHOLMOD"]
    print("| vertices | k | kac (Python, 1 thread) | " + " | ".join(names) + " | lapy+cholespy / kac | max rel. diff |")
    print("|---|---|---|" + "---|" * len(names) + "---|---|")
    for r in rows:
        cells = [f"{r[n]:.2f} s" if r.get(n) is not None else "—" for n in names]
        ratio = f"{r['lapy+cholespy'] / r['kac']:.1f}×" if r.get("lapy+cholespy") else "—"
        diff = max((v for key, v in r.items() if key.endswith("diff")), default=float("nan"))
        print(f"| {r['vertices']:,} | {r['k']} | {r['kac']:.2f} s | " + " | ".join(cells) + f" | {ratio} | {diff:.1e} |")
    if stop:
        print(
            f"\nCtrl-C: icosphere level {stop['level']}, k = {stop['k']}: {stop['outcome']} "
            f"{stop['seconds_after_sigint']:.2f} s after SIGINT (sent 3 s into the solve)."
        )


if __name__ == "__main__":
    main()
