#!/usr/bin/env bash
# Load test of the running service with wrk (Debian package `wrk`): (a) cache-hit result GETs, (b) uploads of a
# 10,242-vertex mesh, (c) job submission past saturation (must answer 503 + Retry-After, no other 5xx).
# Starts its own release server on a free port; prints one JSON line per scenario.
# Usage: bash bench/load.sh   (env: DURATION=10s CONNECTIONS=32 THREADS=2)
set -euo pipefail
cd "$(dirname "$0")/.."
command -v wrk > /dev/null || { echo "install wrk: apt-get install wrk"; exit 1; }
DURATION=${DURATION:-10s}
CONNECTIONS=${CONNECTIONS:-32}
THREADS=${THREADS:-2}
cargo build --release --locked --bin kac > /dev/null
WORK=$(mktemp -d)
export KAC_LOAD_DIR="$PWD/bench/load"
KAC_ADDR=127.0.0.1:0 KAC_DATA_DIR="$WORK/data" KAC_WORKERS=2 KAC_QUEUE_CAPACITY=16 RUST_LOG=error \
  target/release/kac serve > "$WORK/serve.out" 2> "$WORK/serve.err" &
PID=$!
trap 'kill $PID 2>/dev/null || true; rm -rf "$WORK"' EXIT
for _ in $(seq 1 100); do
  ADDR=$(sed -n 's/.*"listening":"\([^"]*\)".*/\1/p' "$WORK/serve.out"); [ -n "$ADDR" ] && break; sleep 0.1
done
BASE="http://$ADDR"
target/release/kac generate icosphere --level 5 --out "$WORK/sphere.off" > /dev/null
export KAC_LOAD_MESH="$WORK/sphere.off"
SHAPE=$(curl -fsS -X POST "$BASE/v1/shapes?format=off" --data-binary @"$WORK/sphere.off" | sed -n 's/^{"id":"\([0-9a-f]*\)".*/\1/p')
export KAC_LOAD_SHAPE="$SHAPE"
JOB=$(curl -fsS -X POST "$BASE/v1/jobs" -H 'content-type: application/json' \
  -d "{\"shape_id\":\"$SHAPE\",\"analysis\":\"hks\",\"k\":50,\"options\":{\"count\":16}}" | sed -n 's/.*"id":"\([0-9a-f]*\)".*/\1/p')
until curl -fsS "$BASE/v1/jobs/$JOB" | grep -q '"status":"succeeded"'; do sleep 0.2; done
cat > "$WORK/get.lua" <<LUA
dofile("$KAC_LOAD_DIR/report.lua")
LUA
run() {
  local name=$1; shift
  local line
  line=$(wrk -t"$THREADS" -c"$CONNECTIONS" -d"$DURATION" "$@" | grep '^LOAD_JSON' | sed 's/^LOAD_JSON //')
  echo "{\"scenario\":\"$name\",\"connections\":$CONNECTIONS,\"duration\":\"$DURATION\",\"result\":$line}"
}
run "result-get-summary (cache hit, ?values=false)" -s "$WORK/get.lua" "$BASE/v1/results/$JOB?values=false"
run "result-get-full (cache hit, 10,242 x 16 HKS values inline)" -s "$WORK/get.lua" "$BASE/v1/results/$JOB"
run "upload-10k-vertex-off" -s "$KAC_LOAD_DIR/upload.lua" "$BASE"
run "job-submission-past-saturation (2 workers, queue 16)" -s "$KAC_LOAD_DIR/jobs.lua" "$BASE"
kill -TERM $PID; wait $PID || true
