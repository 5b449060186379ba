#!/usr/bin/env bash
# Runs every test of kac on a fresh machine: installs what the tests need, then runs them.
# This is the README's test command; .ci/run calls exactly this script.
set -euo pipefail
cd "$(dirname "$0")/.."

# Shared test meshes: one configurable location (tests skip with a message where it is absent).
export KAC_DATA_DIR="${KAC_DATA_DIR:-$(cd .. && pwd)/shared/data}"

echo "== cargo test (workspace; shared data at $KAC_DATA_DIR)"
cargo test --workspace --locked
