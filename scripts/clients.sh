#!/usr/bin/env bash
# Generated clients, tested against the real server: the Python client openapi-python-client makes from the
# committed openapi/openapi.json (which must generate without a warning or error) runs the README walkthrough
# (tests/clients/walkthrough.py), and the TypeScript types openapi-typescript makes type-check a small client doing
# the same walkthrough with `tsc --strict` (tests/clients/walkthrough.ts), which then runs under node. Also checks
# that every success response of the document has a typed body (204 excepted).
# Usage: scripts/clients.sh [path/to/kac]   (default: target/release/kac). Needs python3 (venv) and node/npm.
set -euo pipefail
cd "$(dirname "$0")/.."
KAC_BIN="${1:-target/release/kac}"
OUT=target/clients
VENV=target/clients-venv
mkdir -p "$OUT"
if [ ! -x "$VENV/bin/openapi-python-client" ] || ! "$VENV/bin/python" -c 'import numpy' 2>/dev/null; then
  python3 -m venv "$VENV"
  "$VENV/bin/pip" install --quiet --disable-pip-version-check 'openapi-python-client==0.29.1' 'numpy>=1.26'
fi
if [ ! -x "$OUT/node/node_modules/.bin/tsc" ] || [ ! -d "$OUT/node/node_modules/@types/node" ]; then
  npm install --silent --no-audit --no-fund --prefix "$OUT/node" 'openapi-typescript@7.13.0' 'typescript@5' '@types/node@20'
fi
# Every 2xx response but 204 has a body with a schema.
python3 - <<'PY'
import json, sys
d = json.load(open("openapi/openapi.json"))
bad = [f"{m.upper()} {p} {c}" for p, item in d["paths"].items() for m, op in item.items()
       for c, r in op.get("responses", {}).items() if c.startswith("2") and c != "204"
       and (not r.get("content") or any(not v.get("schema") for v in r["content"].values()))]
if bad:
    sys.exit("untyped success responses: " + ", ".join(bad))
PY
# The Python client: generated with no warning (the post-hooks that format it are off: no ruff needed).
rm -rf "$OUT/python"
printf 'post_hooks: []\n' > "$OUT/openapi-python-client.yaml"
log=$("$VENV/bin/openapi-python-client" generate --path openapi/openapi.json --meta none \
  --config "$OUT/openapi-python-client.yaml" --output-path "$OUT/python/kac_client" 2>&1) || { echo "$log"; exit 1; }
if grep -qiE 'warning|error' <<<"$log"; then echo "$log"; echo "clients: openapi-python-client warned"; exit 1; fi
# The TypeScript types and the client's type check.
rm -rf "$OUT/ts" && mkdir -p "$OUT/ts"
# --default-non-nullable=false: a field with a default may be left out of a request (the server fills it in).
"$OUT/node/node_modules/.bin/openapi-typescript" openapi/openapi.json --default-non-nullable=false \
  -o "$OUT/ts/kac.d.ts" > /dev/null
cp tests/clients/walkthrough.ts "$OUT/ts/"
"$OUT/node/node_modules/.bin/tsc" --strict --target es2022 --module nodenext --moduleResolution nodenext \
  --types node --typeRoots "$OUT/node/node_modules/@types" --skipLibCheck --outDir "$OUT/ts/js" \
  "$OUT/ts/walkthrough.ts" || { echo "clients: tsc failed"; exit 1; }
# Shapes with known answers, and a real server.
"$KAC_BIN" generate icosphere --level 3 --out "$OUT/sphere.off" > /dev/null
"$KAC_BIN" generate torus --out "$OUT/torus.off" > /dev/null
. scripts/serve_lib.sh
start_kac "$KAC_BIN"
PYTHONPATH="$OUT/python" "$VENV/bin/python" tests/clients/walkthrough.py "http://$ADDR" "$OUT/sphere.off" "$OUT/torus.off"
kill $PID; wait $PID 2>/dev/null || true
start_kac "$KAC_BIN"
node "$OUT/ts/js/walkthrough.js" "http://$ADDR" "$OUT/sphere.off" "$OUT/torus.off"
echo "clients: ok"
