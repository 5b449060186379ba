# Sourced by the scripts that test a real server (contract.sh, peers.sh).
# start_kac BIN [VAR=value ...]: starts `BIN serve` with those variables on a free loopback port and a throwaway
# data directory under $WORK; sets WORK, PID and ADDR; stops the server and removes $WORK on exit.
start_kac() {
  local bin=$1
  shift
  WORK=$(mktemp -d)
  env KAC_ADDR=127.0.0.1:0 KAC_DATA_DIR="$WORK/data" RUST_LOG=warn "$@" "$bin" serve \
    > "$WORK/serve.out" 2> "$WORK/serve.err" &
  PID=$!
  trap 'kill $PID 2>/dev/null || true; wait $PID 2>/dev/null || true; rm -rf "$WORK"' EXIT
  ADDR=
  for _ in $(seq 1 100); do
    ADDR=$(sed -n 's/.*"listening":"\([^"]*\)".*/\1/p' "$WORK/serve.out")
    [ -n "$ADDR" ] && break
    sleep 0.1
  done
  [ -n "$ADDR" ] || { echo "the server did not start"; cat "$WORK/serve.err"; exit 1; }
}
