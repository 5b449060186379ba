#!/usr/bin/env bash
# Runs every test of kac on a fresh machine: installs what the tests need, then runs them.
# This is the README's test command; .ci/run calls exactly this script.
set -euo pipefail
cd "$(dirname "$0")/.."

# Shared test meshes: one configurable location, KAC_TEST_DATA (KAC_DATA_DIR is read too, for the meshes only;
# tests skip with a message where it is absent). KAC_DATA_DIR is also `kac serve`'s store (--data-dir): it is
# unset here, so that no server a test starts could take the meshes' directory for its store.
export KAC_TEST_DATA="${KAC_TEST_DATA:-${KAC_DATA_DIR:-$(cd .. && pwd)/shared/data}}"
unset KAC_DATA_DIR

# What the tests need from Debian: curl (the README walkthrough, the contract script), python3-venv
# (schemathesis), chromium and chromium-driver (the viewer's browser tests) and postgresql (the shared backend's tests start throwaway clusters of their own under target/,
# with the server's initdb and pg_ctl; nothing is configured system-wide). Installed only where missing and
# where we may.
need=()
command -v curl > /dev/null || need+=(curl)
python3 -c 'import venv, ensurepip' 2> /dev/null || need+=(python3-venv)
ls /usr/lib/postgresql/*/bin/initdb > /dev/null 2>&1 || need+=(postgresql)
# The viewer's browser tests drive Debian's chromium (headless, software WebGL) through its chromedriver.
command -v chromium > /dev/null || need+=(chromium)
command -v chromedriver > /dev/null || need+=(chromium-driver)
# The generated clients' tests: node and npm (openapi-typescript, tsc), python3-venv (openapi-python-client).
command -v node > /dev/null || need+=(nodejs)
command -v npm > /dev/null || need+=(npm)
if [ ${#need[@]} -gt 0 ]; then
  if [ "$(id -u)" = 0 ]; then apt-get update -q && DEBIAN_FRONTEND=noninteractive apt-get install -y -q "${need[@]}"
  else echo "please install: ${need[*]}"; exit 1; fi
fi

echo "== cargo test (workspace)"
cargo test --workspace --locked
# The tests on the shared meshes are #[ignore]d (a plain `cargo test` reports them as ignored); here they run
# wherever the data is, and fail rather than skip if it cannot be read.
# So are the PostgreSQL tests (store conformance, many replicas under faults) and the browser tests of the viewer
# (which upload a shared mesh through the page), which need the packages installed above.
if [ -f "$KAC_TEST_DATA/README.md" ]; then
  echo "== shared-data and PostgreSQL tests (data at $KAC_TEST_DATA)"
  cargo test --workspace --locked -- --ignored
else
  echo "== shared-data tests NOT RUN: no shared data at $KAC_TEST_DATA (set KAC_TEST_DATA)"
  echo "== PostgreSQL tests"
  cargo test --locked --test stores --test replicas -- --ignored
fi

echo "== release build (the command docker/Dockerfile runs)"
cargo build --release --locked --bin kac

echo "== python: pip install ./crates/kac-python, mypy, pytest (the CLI's numbers, lapy, Ctrl-C, the client)"
bash scripts/python.sh target/release/kac

echo "== peers: SciPy reads the operator matrices the server serves, and ARPACK agrees with its spectra"
bash scripts/peers.sh target/release/kac

echo "== contract: schemathesis against openapi/openapi.json on the real server"
bash scripts/contract.sh target/release/kac

echo "== clients: Python and TypeScript clients generated from openapi/openapi.json run the walkthrough"
bash scripts/clients.sh target/release/kac
