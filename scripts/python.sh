#!/usr/bin/env bash
# The Python package (crates/kac-python): `pip install ./crates/kac-python` in a venv of its own, its types
# checked by mypy, its generated analysis functions checked against the registry, then pytest (tests/python):
# against the CLI's numbers, against lapy installed beside it, Ctrl-C, error codes, and the client against a real
# `kac serve` (the binary given, default target/release/kac).
set -euo pipefail
cd "$(dirname "$0")/.."
KAC_BIN="$(pwd)/${1:-target/release/kac}"
VENV=target/python-venv
[ -x "$VENV/bin/python" ] || python3 -m venv "$VENV"
"$VENV/bin/pip" install --quiet --disable-pip-version-check 'pytest>=8' 'lapy==1.7.0' 'scipy>=1.10' 'mypy>=1.10'
"$VENV/bin/pip" install --quiet --disable-pip-version-check --force-reinstall --no-deps ./crates/kac-python
"$VENV/bin/pip" install --quiet --disable-pip-version-check ./crates/kac-python
"$VENV/bin/mypy" --ignore-missing-imports crates/kac-python/python/kac
"$VENV/bin/python" crates/kac-python/tools/gen_analyses.py --check \
  || { echo "python: _analyses.py is not what tools/gen_analyses.py writes: run it and commit"; exit 1; }
# From outside the source tree, so that the installed package is the one imported.
cd tests/python
KAC_BIN="$KAC_BIN" "../../$VENV/bin/python" -m pytest -q -p no:cacheprovider .
