#!/usr/bin/env bash
# Runs the tests of kac-core's unsafe code under a memory checker, so that an out-of-bounds read or write in a
# SIMD kernel fails the run even where it would leave every value the tests compare intact:
#   - crates/kac-core/tests/unsafe_boundaries.rs: every safe entry point that reaches unsafe code (the supernodal
#     block solve, the basis products, the sparse block product) fed wrong sizes and reversed, strided, transposed
#     and interior views, on every instruction set the CPU has;
#   - the kernels' unit tests in spectrum::basis_products (widths, remainders, every instruction set).
#
# Usage: scripts/sanitize.sh [asan|valgrind]   (default: asan where it is available, else valgrind)
#
#   asan      AddressSanitizer (`-Zsanitizer=address`), which needs a nightly toolchain with its runtime
#             (`rustup toolchain install nightly`). It instruments every load and store of the crate and its
#             dependencies, the kernels' AVX2 and AVX-512 vector accesses included, and checks them against the
#             exact extent of each allocation (stack and heap). Built for an explicit --target so build scripts and
#             proc macros are not instrumented, into target/sanitize so the normal build is left alone.
#   valgrind  memcheck on the stable build: no nightly needed, but heap only, and valgrind hides AVX-512 from the
#             program (its CPUID has none), so only the AVX2 + FMA and portable kernels run; about 30× slower.
#
# Not Miri: it needs the nightly `miri` component, interprets faer's factorization of the fixture far too slowly to
# be useful, and supports only part of the x86 intrinsics the kernels are made of.
# Not part of .ci/run (minutes of instrumented build); run it after touching unsafe code.
set -euo pipefail
cd "$(dirname "$0")/.."

mode="${1:-}"
host="$(rustc -vV | sed -n 's/^host: //p')"
asan_available() {
  command -v rustup > /dev/null && rustc +nightly -vV > /dev/null 2>&1 \
    && compgen -G "$(rustc +nightly --print sysroot)/lib/rustlib/$host/lib/*rt.asan*" > /dev/null
}
if [ -z "$mode" ]; then
  if asan_available; then mode=asan; else mode=valgrind; fi
fi

case "$mode" in
  asan)
    asan_available || { echo "asan needs a nightly toolchain with the ASan runtime (rustup toolchain install nightly)"; exit 1; }
    echo "== AddressSanitizer (nightly, $host)"
    export RUSTFLAGS="-Zsanitizer=address ${RUSTFLAGS:-}"
    export RUSTDOCFLAGS="-Zsanitizer=address"
    # Any report fails the run; leaks are not the question here (and static fixtures are still reachable).
    export ASAN_OPTIONS="detect_leaks=0:abort_on_error=1:${ASAN_OPTIONS:-}"
    common=(+nightly test -p kac-core --locked --target "$host" --target-dir target/sanitize)
    cargo "${common[@]}" --test unsafe_boundaries
    cargo "${common[@]}" --lib -- spectrum::basis_products
    ;;
  valgrind)
    command -v valgrind > /dev/null || { echo "please install valgrind"; exit 1; }
    echo "== valgrind memcheck (stable; AVX-512 hidden by valgrind, so AVX2 + FMA and portable kernels)"
    bins=$(cargo test -p kac-core --locked --no-run --test unsafe_boundaries --lib --message-format=json 2> /dev/null \
      | python3 -c 'import json, sys
for line in sys.stdin:
    m = json.loads(line)
    if m.get("reason") == "compiler-artifact" and m.get("executable") and m["profile"]["test"]:
        print(m["executable"])')
    for bin in $bins; do
      filter=()
      case "$(basename "$bin")" in unsafe_boundaries-*) ;; *) filter=(spectrum::basis_products) ;; esac
      echo "-- $bin ${filter[*]}"
      valgrind --quiet --error-exitcode=1 --leak-check=no "$bin" --test-threads=2 "${filter[@]}"
    done
    ;;
  *)
    echo "usage: $0 [asan|valgrind]"
    exit 2
    ;;
esac
echo "== sanitize ($mode): no memory errors"
