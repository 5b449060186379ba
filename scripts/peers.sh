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
. scripts/serve_lib.sh
start_kac "$KAC_BIN"
"$VENV/bin/python" tests/peers/operator_scipy.py "$ADDR"
