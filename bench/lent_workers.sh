#!/usr/bin/env bash
# One large-k job in the service, alone on a replica of two workers with one solver thread each (issue 31): its
# spectrum slices on the worker that claimed it and on the idle one lent to it, against the same solve on one thread
# (what such a job got before workers were lent) and on two (`kac spectrum --threads`), in the same run. Mesh: the
# 163,842-vertex unit icosphere (bench/out/ico7.off), K pairs (default 1000). Prints one line per run: wall seconds
# (the job: from submission to its end), the workers that solved slices, and peak RSS (the server's: VmHWM). The
# server runs with its default limits (before 994cc2b its --max-output-values refused this job, counting the basis of
# one run). CLI_THREADS="1 2" (default) selects the CLI runs; CLI_THREADS="" runs the service alone.
set -euo pipefail
cd "$(dirname "$0")/.."
K=${K:-1000}
out=bench/out; mkdir -p "$out"
cargo build -q --release
f="$out/ico7.off"
[ -f "$f" ] || ./target/release/kac generate icosphere --level 7 --out "$f" > /dev/null
for t in ${CLI_THREADS-1 2}; do
  /usr/bin/time -f "%M" -o "$out/rss" ./target/release/kac spectrum "$f" -k "$K" --threads "$t" --method sparse \
    > "$out/lent-cli-$t.json"
  python3 - "$out/lent-cli-$t.json" "$t" "$(cat "$out/rss")" <<'PY'
import json, sys
d = json.load(open(sys.argv[1])); t = d["timings"]; s = d["solver"]
print(f"cli --threads {sys.argv[2]}: {t['total_s'] - t.get('read_s', 0):.2f} s, slices {len(s.get('slices', []))}, "
      f"peak {int(sys.argv[3]) / 1e6:.2f} GB")
PY
done
dir=$(mktemp -d)
./target/release/kac serve --addr 127.0.0.1:0 --data-dir "$dir" --workers 2 --solver-threads 1 > "$dir/out" \
  2> /dev/null &
pid=$!
trap 'kill $pid 2> /dev/null; rm -rf "$dir"' EXIT
for _ in $(seq 100); do [ -s "$dir/out" ] && break; sleep 0.1; done
base="http://$(python3 -c 'import json,sys; print(json.loads(open(sys.argv[1]).readline())["listening"])' "$dir/out")"
python3 - "$base" "$f" "$K" "$pid" <<'PY'
import json, sys, time, urllib.request
base, path, k = sys.argv[1], sys.argv[2], int(sys.argv[3])
def call(method, url, body=None, kind="application/json"):
    req = urllib.request.Request(base + url, data=body, method=method, headers={"Content-Type": kind})
    with urllib.request.urlopen(req) as r:
        return json.loads(r.read() or b"null")
shape = call("POST", "/v1/shapes?format=off", open(path, "rb").read(), "application/octet-stream")["id"]
t0 = time.monotonic()
job = call("POST", "/v1/jobs", json.dumps({"shape_id": shape, "analysis": "spectrum", "k": k}).encode())["id"]
while (v := call("GET", f"/v1/jobs/{job}"))["status"] not in ("succeeded", "failed", "canceled"):
    time.sleep(0.05)
wall = time.monotonic() - t0
assert v["status"] == "succeeded", v
res = call("GET", v["result"] + "?values=false")
workers = sorted({s["worker"] for s in res["solver"]["slices"]})
hwm = next(int(l.split()[1]) for l in open(f"/proc/{sys.argv[4]}/status") if l.startswith("VmHWM"))
print(f"service, 2 workers x 1 solver thread: {wall:.2f} s, slices {len(res['solver']['slices'])} on workers "
      f"{workers}, server peak {hwm / 1e6:.2f} GB")
PY
