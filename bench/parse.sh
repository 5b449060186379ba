#!/usr/bin/env bash
# Parsing speed and memory of a 1M-triangle mesh (binary PLY, OBJ, ASCII STL). Prints a Markdown table.
set -euo pipefail
cd "$(dirname "$0")/.."
cargo bench -p kac-core --bench parse 2>/dev/null | grep '^|'
