#!/usr/bin/env bash
# Peer checks over HTTP: a real server on loopback, and SciPy (in the contract venv) reading what it serves.
# Usage: scripts/peers.sh [path/to/kac]   (default: target/release/kac)
set -euo pipefail
cd "$(dirname "$0")/.."
KAC_BIN="${1:-target/release/kac}"
VENV=target/contract-venv
[ -x "$VENV/bin/python" ] || python3 -m venv "$VENV"
"$VENV/bin/python" -c 'import numpy, scipy' 2> /dev/null ||
  "$VENV/bin/pip" install --quiet --disable-pip-version-check 'numpy==2.4.6' 'scipy==1.17.1'
WORK=$(mktemp -d)
KAC_ADDR=127.0.0.1:0 KAC_DATA_DIR="$WORK/data" RUST_LOG=warn "$KAC_BIN" serve > "$WORK/serve.out" 2> "$WORK/serve.err" &
PID=$!
trap 'kill $PID 2>/dev/null || true; wait $PID 2>/dev/null || true; rm -rf "$WORK"' EXIT
for _ in $(seq 1 100); do
  ADDR=$(sed -n 's/.*"listening":"\([^"]*\)".*/\1/p' "$WORK/serve.out")
  [ -n "$ADDR" ] && break
  sleep 0.1
done
[ -n "${ADDR:-}" ] || { echo "the server did not start"; cat "$WORK/serve.err"; exit 1; }
"$VENV/bin/python" tests/peers/operator_scipy.py "$ADDR"
