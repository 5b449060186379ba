#!/usr/bin/env bash
# k smallest eigenpairs of P1 FEM (consistent mass) on unit icospheres: kac (1 and 2 threads) against scipy eigsh
# (ARPACK shift-invert with SuperLU or with CHOLMOD from scikit-sparse) and lapy (with SuperLU or with cholespy), in
# one run, on the same files. Peers are single-threaded (OPENBLAS_NUM_THREADS=1). Prints a Markdown table; raw lines
# in bench/out/spectrum.jsonl. Installs Debian's libsuitesparse-dev (for scikit-sparse) when it is missing.
# CASES="level:k ..." selects rows (default: the issue's table; the 163,842-vertex rows take minutes). REPS=N runs
# every program N times, interleaved, and reports each one's fastest run (default 1; use 3 on a noisy machine).
set -euo pipefail
cd "$(dirname "$0")/.."
out=bench/out; mkdir -p "$out"
if [ ! -f /usr/include/suitesparse/cholmod.h ]; then
  sudo=""; [ "$(id -u)" = 0 ] || sudo=sudo
  $sudo apt-get install -y -q libsuitesparse-dev > /dev/null
fi
if [ ! -x bench/.venv/bin/python ]; then python3 -m venv bench/.venv; fi
bench/.venv/bin/pip install -q numpy scipy lapy cholespy "scikit-sparse==0.4.16"
cargo build -q --release
CASES=${CASES:-"5:50 6:50 6:200 7:50"}
: > "$out/spectrum.jsonl"
for c in $CASES; do
  level=${c%%:*}; k=${c##*:}
  f="$out/ico$level.off"
  [ -f "$f" ] || ./target/release/kac generate icosphere --level "$level" --out "$f" > /dev/null
  for rep in $(seq "${REPS:-1}"); do
  for t in 1 2; do
    /usr/bin/time -f "%M" -o "$out/rss" ./target/release/kac spectrum "$f" -k "$k" --threads "$t" --method sparse > "$out/kac-$level-$k-$t.json"
    python3 - "$out/kac-$level-$k-$t.json" "$t" "$(cat "$out/rss")" >> "$out/spectrum.jsonl" <<'PY'
import json, sys
d = json.load(open(sys.argv[1]))
print(json.dumps({"vertices": d["size"], "k": d["k"], "peer": f"kac-{sys.argv[2]}t", "seconds": d["timings"]["total_s"] - d["timings"]["read_s"],
                  "peak_bytes": int(sys.argv[3]) * 1024, "max_residual": max(d["residuals"]), "solver": d["solver"], "timings": d["timings"]}))
PY
  done
  for peer in scipy-superlu scipy-cholmod lapy lapy-cholespy; do
    OPENBLAS_NUM_THREADS=1 OMP_NUM_THREADS=1 bench/.venv/bin/python bench/spectrum_peers.py "$peer" "$f" "$k" "$out/kac-$level-$k-1.json" >> "$out/spectrum.jsonl"
  done
  done
done
python3 - "$out/spectrum.jsonl" <<'PY'
import json, sys
rows = [json.loads(l) for l in open(sys.argv[1]) if l.strip()]
by = {}
for r in rows:  # each program's fastest run
    cell = by.setdefault((r["vertices"], r["k"]), {})
    if r["peer"] not in cell or r["seconds"] < cell[r["peer"]]["seconds"]:
        cell[r["peer"]] = r
names = ("scipy-superlu", "scipy-cholmod", "lapy", "lapy-cholespy")
print("| vertices | k | kac 1 thread | kac 2 threads | scipy+SuperLU | scipy+CHOLMOD | lapy | lapy+cholespy | best peer / kac (1t) | peak memory kac / best peer | max rel. diff of eigenvalues | kac max residual |")
print("|---|---|---|---|---|---|---|---|---|---|---|---|")
for (n, k), d in sorted(by.items()):
    k1, k2 = d["kac-1t"], d["kac-2t"]
    peers = [d[p] for p in names if p in d]
    best = min(peers, key=lambda r: r["seconds"])
    diff = max(p["max_rel_diff_vs_kac"] for p in peers)
    print(f"| {n:,} | {k} | {k1['seconds']:.2f} s | {k2['seconds']:.2f} s | " + " | ".join(f"{d[p]['seconds']:.2f} s" if p in d else "—" for p in names)
          + f" | {best['seconds']/k1['seconds']:.2f}× | {k1['peak_bytes']/1e6:.0f} MB / {best['peak_bytes']/1e6:.0f} MB | {diff:.1e} | {k1['max_residual']:.1e} |")
PY
