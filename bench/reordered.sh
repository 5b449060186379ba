#!/usr/bin/env bash
# The solver's plan on any vertex order (issue 48): the 163,842-vertex unit icosphere as `kac generate icosphere
# --level 7` numbers it and as ../shared/tools/icosphere_reordered.py numbers it (the same geometry, another vertex and
# face order), k = 200 and k = 1000 on two threads. Prints a Markdown table: wall time and peak RSS (/usr/bin/time),
# slices, whether the plan changed (solver.plan), and each order's k = 1000 time over its k = 200 time. Needs NumPy
# for the reordering script (a venv under bench/.venv). SHARED (default ../shared) locates the tools.
set -euo pipefail
cd "$(dirname "$0")/.."
out=bench/out; mkdir -p "$out"
shared=${SHARED:-../shared}
if [ ! -x bench/.venv/bin/python ]; then python3 -m venv bench/.venv; fi
bench/.venv/bin/python -c 'import numpy' 2> /dev/null || bench/.venv/bin/pip install -q numpy
cargo build -q --release --bin kac
[ -f "$out/ico7.off" ] || ./target/release/kac generate icosphere --level 7 --out "$out/ico7.off" > /dev/null
[ -f "$out/ico7-reordered.obj" ] || bench/.venv/bin/python "$shared/tools/icosphere_reordered.py" 7 "$out/ico7-reordered.obj"
echo "| order | k | wall | peak RSS | slices | plan changed | k = 1000 / k = 200 |"
echo "|---|---|---|---|---|---|---|"
for mesh in ico7.off ico7-reordered.obj; do
  base=""
  for k in 200 1000; do
    /usr/bin/time -f "%e %M" -o "$out/time.txt" ./target/release/kac spectrum "$out/$mesh" -k "$k" --threads 2 \
      > "$out/reordered.json" 2> /dev/null
    read -r wall kb < "$out/time.txt"
    row=$(python3 - "$out/reordered.json" "$wall" "$kb" "${base:-0}" <<'EOF'
import json, sys
d = json.load(open(sys.argv[1]))
wall, kb, base = float(sys.argv[2]), int(sys.argv[3]), float(sys.argv[4])
s = d["solver"]
ratio = f"{wall / base:.2f}×" if base > 0 else ""
plan = s.get("plan")
changed = f"yes: {plan['planned']} → {plan['taken']} ({plan['reason']})" if plan else "no"
print(f"{len(s.get('slices', []))}|{changed}|{ratio}|{wall:.1f} s|{kb / 1e6:.2f} GB")
EOF
)
    IFS='|' read -r slices changed ratio w gb <<< "$row"
    echo "| ${mesh%%.*} | $k | $w | $gb | $slices | $changed | $ratio |"
    [ -n "$base" ] || base=$wall
  done
done
