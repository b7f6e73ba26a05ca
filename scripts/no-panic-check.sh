#!/usr/bin/env bash
# Link-time proof that the Cortex-M4 firmware (FlightCore::new/step, table loads, telemetry
# encoders, postcard decoding of the fixture, defmt logging) has no panic path.
#
#   scripts/no-panic-check.sh [--no-self-test]
#
# Builds firmware/'s `no-panic` binary (the replay program whose #[panic_handler] calls an
# undefined extern function) with the firmware release profile: lto = "fat",
# codegen-units = 1, panic = "abort", opt-level = 3. It links only if no call to the panic
# handler survives optimisation.
#
# If the link fails, the surviving panic call sites are listed from the `replay` binary (same
# program, ordinary handler): every call into the panic machinery (core::panicking::*,
# bounds/slice/unwrap failures, ...) from a function outside `core`, with `addr2line -i`'s
# inline chain, innermost frame first: the first frame outside core/ is the responsible source
# line (fsw-core file:line or the dependency function).
#
# Self-test (default): the `no-panic-canary` feature adds one reachable out-of-bounds index;
# the check must then fail and the listing must name firmware/src/lib.rs. This shows that the
# passing result is not an artefact of the set-up.
#
# Exit status: 0 no panic path; 1 panic paths survive (listed); 2 build/set-up error.
set -euo pipefail

ROOT="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
FW="$ROOT/firmware"
TARGET=thumbv7em-none-eabihf
SYMBOL=fsw_firmware_panic_path_survives_optimisation
SELF_TEST=1
for arg in "$@"; do
  case "$arg" in
    --no-self-test) SELF_TEST=0 ;;
    -h | --help) sed -n '2,22p' "$0"; exit 0 ;;
    *) echo "unknown argument: $arg" >&2; exit 2 ;;
  esac
done
export PATH="$HOME/.cargo/bin:$PATH"

if ! rustup target list --installed | grep -qx "$TARGET"; then
  rustup target add "$TARGET"
fi
objdump_tool() {
  if command -v llvm-objdump >/dev/null; then echo llvm-objdump; else
    local t; t="$(find "$(rustc --print sysroot)" -name llvm-objdump -type f 2>/dev/null | head -n1)"
    [ -n "$t" ] && echo "$t" || { echo "llvm-objdump not found (rustup component add llvm-tools)" >&2; exit 2; }
  fi
}
OBJDUMP="$(objdump_tool)"
command -v addr2line >/dev/null || { echo "addr2line not found (apt-get install binutils)" >&2; exit 2; }

# list_panic_sites ELF: print each call into the panic machinery from outside core.
list_panic_sites() {
  local elf="$1" dis
  dis="$(mktemp)"
  "$OBJDUMP" -d --no-show-raw-insn -C "$elf" >"$dis"
  # Edges "caller<TAB>site<TAB>callee" for direct branches/calls to a function start.
  awk '
    /^[0-9a-f]+ <.*>:$/ { f = $0; sub(/^[0-9a-f]+ </, "", f); sub(/>:$/, "", f); next }
    /\t(bl|blx|b|b\.w|bne\.w|beq\.w|bhi\.w|blo\.w|bhs\.w|bls\.w|bgt\.w|bge\.w|blt\.w|ble\.w|b[a-z][a-z])\t/ && /<[^>+]+>/ {
      site = $1; sub(/:$/, "", site)
      t = $0; sub(/^[^<]*</, "", t); sub(/>.*$/, "", t)
      if (t != f) print f "\t" site "\t" t
    }' "$dis" | sort -u >"$dis.edges"
  # Panic set: the handler, then every core:: function that reaches it.
  awk -F'\t' '
    { caller[NR] = $1; callee[NR] = $3; site[NR] = $2; n = NR }
    END {
      for (i = 1; i <= n; i++) if (callee[i] ~ /rust_begin_unwind$/) p[callee[i]] = 1
      changed = 1
      while (changed) {
        changed = 0
        for (i = 1; i <= n; i++)
          if ((callee[i] in p) && !(caller[i] in p) && caller[i] ~ /^(core::|<core::)/) { p[caller[i]] = 1; changed = 1 }
      }
      for (i = 1; i <= n; i++)
        if ((callee[i] in p) && !(caller[i] in p) && caller[i] !~ /rust_begin_unwind$/)
          print site[i] "\t" caller[i] "\t" callee[i]
    }' "$dis.edges" >"$dis.sites"
  local count
  count="$(wc -l <"$dis.sites")"
  echo "surviving panic call sites in $(basename "$elf"): $count"
  while IFS=$'\t' read -r addr caller callee; do
    echo "- 0x$addr in $caller -> $callee"
    addr2line -i -f -C -e "$elf" "0x$addr" | paste - - | awk -F'\t' '
      { loc = $2; sub(/.*\/registry\/src\/[^\/]+\//, "", loc); sub(/.*\/rustlib\/src\/rust\//, "", loc); sub("^'"$ROOT"'/", "", loc)
        mark = (!done && loc !~ /^library\/core\//) ? "  <== responsible" : ""; if (mark != "") done = 1
        printf "    %s  %s%s\n", $1, loc, mark }'
  done <"$dis.sites"
  rm -f "$dis" "$dis.edges" "$dis.sites"
}

# build_no_panic [cargo args...]: 0 linked, 1 undefined panic symbol, 2 other error.
build_no_panic() {
  local log
  log="$(mktemp)"
  if (cd "$FW" && cargo build --release --bin no-panic "$@") >"$log" 2>&1; then
    rm -f "$log"; return 0
  fi
  if grep -q "undefined symbol: $SYMBOL" "$log"; then
    grep -E "undefined symbol|referenced by" "$log" | head -n 4 | sed 's/^ */    /'
    rm -f "$log"; return 1
  fi
  cat "$log" >&2; rm -f "$log"; return 2
}

echo "== no-panic check: firmware/ bin no-panic, $TARGET, release (lto=fat, codegen-units=1, panic=abort, opt-level=3)"
status=0
build_no_panic || status=$?
ELF="$FW/target/$TARGET/release/no-panic"
case "$status" in
  0)
    echo "PASS: the no-panic binary linked: no panic path survives in the firmware"
    size "$ELF" | sed 's/^/    /'
    ;;
  1)
    echo "FAIL: panic paths survive; call sites from the replay binary (same program, ordinary handler):"
    (cd "$FW" && cargo build --release --bin replay) >/dev/null 2>&1 || { echo "replay build failed" >&2; exit 2; }
    list_panic_sites "$FW/target/$TARGET/release/replay"
    exit 1
    ;;
  *) echo "ERROR: the no-panic binary did not build for another reason (above)" >&2; exit 2 ;;
esac

if [ "$SELF_TEST" = 1 ]; then
  echo "== self-test: with the no-panic-canary feature (one reachable out-of-bounds index) the link must fail"
  canary_status=0
  build_no_panic --features no-panic-canary --target-dir "$FW/target/canary" || canary_status=$?
  if [ "$canary_status" != 1 ]; then
    echo "SELF-TEST FAIL: the canary build did not fail on the panic symbol (status $canary_status)" >&2
    exit 2
  fi
  (cd "$FW" && cargo build --release --bin replay --features no-panic-canary --target-dir "$FW/target/canary") >/dev/null 2>&1
  sites="$(list_panic_sites "$FW/target/canary/$TARGET/release/replay")"
  echo "$sites"
  if ! grep -q "firmware/src/lib.rs.*responsible" <<<"$sites"; then
    echo "SELF-TEST FAIL: the listing did not locate the canary in firmware/src/lib.rs" >&2
    exit 2
  fi
  echo "self-test PASS: the check detects and locates a surviving panic"
fi
