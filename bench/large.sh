#!/usr/bin/env bash
# Many eigenpairs and large meshes (issue 31): kac on one thread and on two (default plan: spectrum slicing from 400
# pairs) and in one run (--slices 1, two threads), beside scipy eigsh + CHOLMOD and lapy + cholespy on the same files
# in the same run (single-threaded, OPENBLAS_NUM_THREADS=1). Peak memory is each process' max RSS. A peer that runs
# past PEER_TIMEOUT seconds (default 600) is recorded as such. Prints a Markdown table; raw lines in
# bench/out/large.jsonl. Same set-up as bench/spectrum.sh (Debian's libsuitesparse-dev, a venv under bench/.venv).
# CASES="mesh:k ..." selects rows: mesh is ico7 (the 163,842-vertex unit icosphere) or square1000 (the unit square's
# 1001 × 1001 grid, 1,002,001 vertices, Neumann). PEERS="" skips the peers.
set -euo pipefail
cd "$(dirname "$0")/.."
out=bench/out; mkdir -p "$out"
if [ -n "${PEERS-x}" ]; then
  if [ ! -f /usr/include/suitesparse/cholmod.h ]; then
    sudo=""; [ "$(id -u)" = 0 ] || sudo=sudo
    $sudo apt-get install -y -q libsuitesparse-dev > /dev/null
  fi
  if [ ! -x bench/.venv/bin/python ]; then python3 -m venv bench/.venv; fi
  bench/.venv/bin/pip install -q numpy scipy lapy cholespy "scikit-sparse==0.4.16"
fi
PEERS=${PEERS-"scipy-cholmod lapy-cholespy"}
cargo build -q --release
CASES=${CASES:-"ico7:200 ico7:1000 square1000:100"}
: > "$out/large.jsonl"
for c in $CASES; do
  mesh=${c%%:*}; k=${c##*:}
  f="$out/$mesh.off"
  case $mesh in
    ico7) [ -f "$f" ] || ./target/release/kac generate icosphere --level 7 --out "$f" > /dev/null ;;
    square1000) [ -f "$f" ] || ./target/release/kac generate square --n 1000 --out "$f" > /dev/null ;;
    *) echo "unknown mesh $mesh" >&2; exit 2 ;;
  esac
  for run in "1 auto" "2 auto" "2 1"; do
    set -- $run
    t=$1; s=$2; flags=(); [ "$s" = auto ] || flags=(--slices "$s")
    name="kac-${t}t"; [ "$s" = auto ] || name="kac-${t}t-slices$s"
    /usr/bin/time -f "%M" -o "$out/rss" ./target/release/kac spectrum "$f" -k "$k" --threads "$t" --method sparse \
      "${flags[@]}" > "$out/kac-$mesh-$k-$name.json"
    python3 - "$out/kac-$mesh-$k-$name.json" "$name" "$(cat "$out/rss")" >> "$out/large.jsonl" <<'PY'
import json, sys
d = json.load(open(sys.argv[1]))
s = d["solver"]
print(json.dumps({"vertices": d["size"], "k": d["k"], "peer": sys.argv[2], "seconds": d["timings"]["total_s"] - d["timings"]["read_s"],
                  "peak_bytes": int(sys.argv[3]) * 1024, "max_residual": max(d["residuals"]), "slices": len(s.get("slices", [])),
                  "complete": s["completeness"]["complete"], "block_steps": s["block_steps"], "timings": d["timings"]}))
PY
  done
  for peer in $PEERS; do
    rc=0
    OPENBLAS_NUM_THREADS=1 OMP_NUM_THREADS=1 timeout "${PEER_TIMEOUT:-600}" bench/.venv/bin/python bench/spectrum_peers.py \
      "$peer" "$f" "$k" "$out/kac-$mesh-$k-kac-1t.json" >> "$out/large.jsonl" || rc=$?
    if [ "$rc" = 124 ]; then
      python3 -c "import json,sys; print(json.dumps({'vertices': int(sys.argv[1]), 'k': int(sys.argv[2]), 'peer': sys.argv[3], 'timed_out': int(sys.argv[4])}))" \
        "$(python3 -c "import json; print(json.load(open('$out/kac-$mesh-$k-kac-1t.json'))['size'])")" "$k" "$peer" "${PEER_TIMEOUT:-600}" >> "$out/large.jsonl"
    elif [ "$rc" != 0 ]; then exit "$rc"; fi
  done
done
python3 - "$out/large.jsonl" <<'PY'
import json, sys
rows = [json.loads(l) for l in open(sys.argv[1]) if l.strip()]
by = {}
for r in rows:
    by.setdefault((r["vertices"], r["k"]), {})[r["peer"]] = r
peers = ("scipy-cholmod", "lapy-cholespy")
def cell(r):
    if r is None: return "—"
    if "timed_out" in r: return f"> {r['timed_out']} s"
    return f"{r['seconds']:.2f} s"
print("| vertices | k | kac 1 thread | kac 2 threads | kac 2 threads, one run | scipy+CHOLMOD | lapy+cholespy | best peer / kac (1t) | 2 threads / 1 thread | peak memory kac 1t / 2t / one run | slices | max rel. diff of eigenvalues | kac max residual |")
print("|---|---|---|---|---|---|---|---|---|---|---|---|---|")
for (n, k), d in sorted(by.items()):
    k1, k2, one = d.get("kac-1t"), d.get("kac-2t"), d.get("kac-2t-slices1")
    done = [d[p] for p in peers if p in d and "seconds" in d[p]]
    best = min(done, key=lambda r: r["seconds"]) if done else None
    ratio = f"{best['seconds'] / k1['seconds']:.2f}×" if best else (f"> {min(d[p]['timed_out'] for p in peers if p in d) / k1['seconds']:.1f}×" if any(p in d for p in peers) else "—")
    diff = f"{max(p['max_rel_diff_vs_kac'] for p in done):.1e}" if done else "—"
    mem = " / ".join(f"{r['peak_bytes'] / 1e9:.2f} GB" if r else "—" for r in (k1, k2, one))
    print(f"| {n:,} | {k} | {cell(k1)} | {cell(k2)} | {cell(one)} | " + " | ".join(cell(d.get(p)) for p in peers)
          + f" | {ratio} | {k1['seconds'] / k2['seconds']:.2f}× | {mem} | {k1['slices']} | {diff} | {max(r['max_residual'] for r in (k1, k2, one) if r):.1e} |")
PY
