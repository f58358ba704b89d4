#!/usr/bin/env bash
# Cost and size report of the firmware: prints a Markdown table.
#
#   firmware/report.sh            # 500 Hz build
#   FEATURES=loop-1khz firmware/report.sh
#
# Needs qemu-system-arm and either arm-none-eabi-size (binutils-arm-none-eabi) or llvm-size
# (rustup component llvm-tools); adds the thumbv7em-none-eabihf target itself when missing.
# From the repository root: `cargo fw-report` (same arguments and FEATURES). Budgets (DESIGN.md): step <= 20,000 instructions (~150 us at
# 168 MHz), flash <= 128 KiB with the weights, static RAM <= 32 KiB.
set -euo pipefail
cd "$(dirname "$0")"
# Adds the thumbv7em target if rustup did not (toolchain installed before rust-toolchain.toml).
tools/ensure-target.sh

extra="${FEATURES:-}"
feat_board="${extra}"
feat_bench="bench${extra:+,$extra}"

echo "building (release) ..." >&2
cargo build --release --bin crazyflie ${feat_board:+--features "$feat_board"} >&2
cargo build --release --bin qemu --features "$feat_bench" >&2
tdir="${CARGO_TARGET_DIR:-target}/thumbv7em-none-eabihf/release"
elf_board="$tdir/crazyflie"
elf_qemu="$tdir/qemu"

if command -v arm-none-eabi-size >/dev/null; then
  size_tool=arm-none-eabi-size
else
  size_tool="$(find "$(rustc --print sysroot)" -name llvm-size -type f | head -n1)"
  [ -n "$size_tool" ] || { echo "need arm-none-eabi-size or llvm-size (rustup component add llvm-tools)" >&2; exit 1; }
fi
command -v qemu-system-arm >/dev/null || { echo "need qemu-system-arm (apt-get install qemu-system-arm)" >&2; exit 1; }

# Section sizes in bytes (SysV format: name size addr).
sec() { "$size_tool" -A "$elf_board" | awk -v s="$1" '$1==s {print $2; f=1} END {if(!f) print 0}'; }
flash=$(( $(sec .vector_table) + $(sec .text) + $(sec .rodata) + $(sec .data) ))
sram=$(( $(sec .data) + $(sec .bss) + $(sec .uninit) ))

echo "running the step benchmark under QEMU (-icount shift=0) ..." >&2
line=$(timeout 120 qemu-system-arm -M netduinoplus2 -nographic -monitor none -serial null \
  -semihosting-config enable=on,target=native -icount shift=0 -kernel "$elf_qemu" | grep '^BENCH' || true)
[ -n "$line" ] || { echo "the QEMU benchmark printed no BENCH line" >&2; exit 1; }
get() { sed -n "s/.* $1=\([0-9]*\).*/\1/p" <<<"$line"; }
steps=$(get steps); total=$(get total); max=$(get max); min=$(get min)
peak=$(get stack_peak); boot=$(get stack_boot_peak); ssize=$(get stack_size); blob_len=$(get blob_len)

# SysTick runs on the 168 MHz core clock of QEMU's netduinoplus2; with -icount shift=0 one
# instruction takes 1 ns of virtual time, so instructions = ticks * 1000 / 168.
# Time at 168 MHz assumes one cycle per instruction (Cortex-M4F: most ALU/FPU ops; loads,
# branches, divisions, sqrt and flash wait states cost more, so the real figure is higher;
# measure with the DWT cycle counter on the board: the telemetry's step_cost there is cycles).
awk -v steps="$steps" -v total="$total" -v max="$max" -v min="$min" -v flash="$flash" \
    -v sram="$sram" -v peak="$peak" -v boot="$boot" -v ssize="$ssize" -v blob="$blob_len" '
function ins(t) { return t * 1000.0 / 168.0 }
BEGIN {
  mean = total / steps
  printf "| quantity | value | budget |\n| --- | --- | --- |\n"
  printf "| control step, mean (%d steps) | %.0f instructions (%.1f us at 168 MHz) | <= 20,000 (150 us) |\n", steps, ins(mean), ins(mean)/168
  printf "| control step, max | %.0f instructions (%.1f us) | |\n", ins(max), ins(max)/168
  printf "| control step, min | %.0f instructions (%.1f us) | |\n", ins(min), ins(min)/168
  printf "| flash (Crazyflie build, incl. %s-byte weight blob) | %d bytes (%.1f KiB) | <= 128 KiB |\n", blob, flash, flash/1024
  printf "| static RAM (.data + .bss + .uninit) | %d bytes (%.1f KiB) | <= 32 KiB |\n", sram, sram/1024
  printf "| peak stack, running (control loop + interrupts) | %d bytes | |\n", peak
  printf "| peak stack, boot (blob check, in-place decode) | %d bytes (of %d free) | |\n", boot, ssize
}'
