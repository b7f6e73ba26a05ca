#!/usr/bin/env bash
# Replay a recorded input sequence through the flight core on an emulated Cortex-M4 and
# check it bit for bit against the host.
#
#   scripts/qemu-replay.sh [--no-regen]
#
# 1. Installs what is missing: the thumbv7em-none-eabihf target, qemu-system-arm (apt),
#    defmt-print (cargo install --locked).
# 2. Regenerates the fixture with the host FlightCore of this work tree
#    (`cargo run -p fsw-core --example replay_record`: firmware/fixtures/replay.bin and
#    replay.expected.bin) and says whether it differs from the committed one. With
#    --no-regen the committed fixture is used as it is.
# 3. Builds firmware/ (bin `replay`, release: fat LTO, opt-level 3) and prints its size and
#    its largest stack frames.
# 4. Runs it under QEMU 7.2 mps2-an386 (Cortex-M4F) with semihosting, decoding the defmt
#    log with defmt-print. The firmware exits with status 0 only if every cycle's output
#    (CUC time + ICD housekeeping record + events) is bit-identical to the host's.
#
# Exit status: 0 bit-identical; non-zero on mismatch, fault, timeout or set-up error.
set -euo pipefail
set -o pipefail

ROOT="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
FW="$ROOT/firmware"
TARGET=thumbv7em-none-eabihf
ELF="$FW/target/$TARGET/release/replay"
REGEN=1
for arg in "$@"; do
  case "$arg" in
    --no-regen) REGEN=0 ;;
    -h | --help) sed -n '2,19p' "$0"; exit 0 ;;
    *) echo "unknown argument: $arg" >&2; exit 2 ;;
  esac
done
export PATH="$HOME/.cargo/bin:$PATH"

echo "== tools"
if ! rustup target list --installed | grep -qx "$TARGET"; then
  rustup target add "$TARGET"
fi
if ! command -v qemu-system-arm >/dev/null; then
  SUDO=""
  [ "$(id -u)" = 0 ] || SUDO=sudo
  $SUDO apt-get update
  DEBIAN_FRONTEND=noninteractive $SUDO apt-get install -y qemu-system-arm
fi
if ! command -v defmt-print >/dev/null; then
  cargo install defmt-print --locked
fi
echo "$(qemu-system-arm --version | head -n1); $(defmt-print --version 2>/dev/null | head -n1 || echo defmt-print)"

if [ "$REGEN" = 1 ]; then
  echo "== fixture: host FlightCore over the recorded scenario"
  (cd "$ROOT" && cargo run --release -q -p fsw-core --example replay_record -- \
    "$FW/fixtures/replay.bin" "$FW/fixtures/replay.expected.bin")
  if git -C "$ROOT" ls-files --error-unmatch firmware/fixtures/replay.bin >/dev/null 2>&1; then
    if git -C "$ROOT" diff --quiet -- firmware/fixtures; then
      echo "fixture identical to the committed one"
    else
      echo "NOTE: the regenerated fixture differs from the committed one (fsw-core's outputs or the"
      echo "      scenario changed since it was committed); the replay uses the regenerated one."
    fi
  fi
else
  echo "== fixture: committed firmware/fixtures (not regenerated)"
fi

echo "== build firmware (release, $TARGET)"
(cd "$FW" && cargo build --release --bin replay)
if command -v llvm-size >/dev/null; then SIZE=llvm-size; else SIZE=size; fi
"$SIZE" "$ELF" | sed 's/^/    /'
if command -v llvm-objdump >/dev/null; then
  echo "stack frames >= 4 KiB (sub sp at function entry):"
  llvm-objdump -d --no-show-raw-insn -C "$ELF" | awk '
    /^[0-9a-f]+ <.*>:$/ { f = $0; sub(/^[0-9a-f]+ </, "", f); sub(/>:$/, "", f); sub(/::h[0-9a-f]+$/, "", f) }
    /sub(\.w)?[ \t]+sp, (sp, )?#[0-9]+/ { match($0, /#[0-9]+/); n = substr($0, RSTART + 1, RLENGTH - 1) + 0
      if (n >= 4096) printf "    %8d B  %s\n", n, f }' | sort -rn | uniq
fi

echo "== run: qemu-system-arm -cpu cortex-m4 -machine mps2-an386 (semihosting) | defmt-print"
LOG="$(mktemp)"
status=0
timeout 600 qemu-system-arm -cpu cortex-m4 -machine mps2-an386 -nographic -monitor none \
  -serial none -semihosting-config enable=on,target=native -kernel "$ELF" \
  | defmt-print -e "$ELF" | tee "$LOG" || status=$?
if [ "$status" = 0 ] && grep -q "RESULT: PASS" "$LOG"; then
  rm -f "$LOG"
  echo "qemu-replay: PASS (bit-identical to the host)"
  exit 0
fi
rm -f "$LOG"
[ "$status" = 124 ] && echo "qemu-replay: TIMEOUT" >&2
echo "qemu-replay: FAIL (status $status)" >&2
exit "$(( status == 0 ? 1 : status ))"
