#!/usr/bin/env bash
# Operator assembly: kac (1 and 2 threads) against libigl, lapy and robust-laplacian on the same icospheres, in
# one run. Installs the peers into bench/.venv from PyPI. Prints a Markdown table for BENCHMARKS.md.
set -euo pipefail
cd "$(dirname "$0")/.."
out=bench/out; mkdir -p "$out"
if [ ! -x bench/.venv/bin/python ]; then python3 -m venv bench/.venv; fi
bench/.venv/bin/pip install -q numpy scipy lapy libigl robust-laplacian
cargo build -q --release
files=()
for level in 5 6 7; do
  ./target/release/kac generate icosphere --level "$level" --out "$out/ico$level.off" > /dev/null
  files+=("$out/ico$level.off")
done
: > "$out/assembly.jsonl"
for t in 1 2; do RAYON_NUM_THREADS=$t cargo bench -q -p kac-core --bench operators 2>/dev/null >> "$out/assembly.jsonl"; done
OPENBLAS_NUM_THREADS=1 OMP_NUM_THREADS=1 bench/.venv/bin/python bench/assembly_peers.py "${files[@]}" >> "$out/assembly.jsonl"
python3 - "$out/assembly.jsonl" <<'PY'
import json, sys
rows = [json.loads(l) for l in open(sys.argv[1]) if l.strip()]
kac = {(r["vertices"], r["threads"]): r["median_s"] for r in rows if r.get("operator") == "cotan" and r.get("mass") == "consistent"}
rob = {(r["vertices"], r["threads"]): r["median_s"] for r in rows if r.get("operator") == "robust"}
peers = {(r["vertices"], r["peer"]): r["median_s"] for r in rows if "peer" in r}
print("| vertices | kac cotan L+M (1 thread) | kac (2 threads) | kac robust (1 thread) | libigl | lapy | robust-laplacian | libigl/kac | lapy/kac | robust-laplacian/kac robust |")
print("|---|---|---|---|---|---|---|---|---|---|")
for n in sorted({k[0] for k in kac}):
    k1, k2, r1 = kac[(n, 1)], kac[(n, 2)], rob[(n, 1)]
    ig, la, rl = peers[(n, "libigl")], peers[(n, "lapy")], peers[(n, "robust-laplacian")]
    print(f"| {n:,} | {k1:.4f} s | {k2:.4f} s | {r1:.4f} s | {ig:.4f} s | {la:.4f} s | {rl:.4f} s | {ig/k1:.1f}× | {la/k1:.1f}× | {rl/r1:.1f}× |")
PY
