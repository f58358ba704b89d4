#!/usr/bin/env bash
# Cost and size report of the firmware: prints a Markdown table.
#
#   firmware/report.sh            # 500 Hz build
#   FEATURES=loop-1khz firmware/report.sh
#
# Needs qemu-system-arm and either arm-none-eabi-size (binutils-arm-none-eabi) or llvm-size
# (rustup component llvm-tools); adds the thumbv7em-none-eabihf target itself when missing.
# From the repository root: `cargo fw-report` (same arguments and FEATURES). Budgets (those
# of docs/design.md): the worst step <= 10,000 instructions for every build (the default, composite, loop-1khz), flash <= 64 KiB
# (the Crazyflie image with the weights, every feature set), static RAM <= 32 KiB, the control
# step's measured stack <= 1,194 B (the arithmetic at the budget below). The table is
# printed first; then the script fails if a budget is exceeded.
# The estimated cycles per step come from QEMU's instruction trace of a 200-step bench
# (tools/trace-profile.py, the Cortex-M4 TRM's timing table); CYCLES=0 skips it (~30 s).
# The control step's stack is measured too: after the counted run the bench steps the controller
# it flew again, through one out-of-line call (`bench::step`, the core's step_into as the
# Crazyflie app's hf_step runs it) with the stack painted below it, over the bench's inputs and
# off-nominal ones (saturation, tilt limit, yaw across +-pi, the accelerometer, the fault paths),
# and prints the deepest word overwritten (the STACK line). bitcraze-app/stack-estimate.py bounds
# the same function in the same ELF from its disassembly: the script fails if the measured
# high-water mark exceeds that bound (the estimator would be missing a path) or the step budget
# below. Needs python3 and arm-none-eabi-objdump for the bound (without them, under CI=true, it
# fails; elsewhere the bound is skipped with a message).
set -euo pipefail
cd "$(dirname "$0")"
# Adds the thumbv7em target if rustup did not (toolchain installed before rust-toolchain.toml).
tools/ensure-target.sh

extra="${FEATURES:-}"
# NO_DEFAULT=1: without the default features (the composite law): the paper's gradient law alone.
# REPORT_KV=FILE: also write the figures as one line of key=value pairs to FILE (for the docs'
# generated budget table, host-train's doc_tables example).
nodef=()
if [ "${NO_DEFAULT:-0}" = 1 ]; then nodef=(--no-default-features); fi
feat_board="${extra}"
feat_bench="bench${extra:+,$extra}"

echo "building (release) ..." >&2
cargo build --release "${nodef[@]}" --bin crazyflie ${feat_board:+--features "$feat_board"} >&2
cargo build --release "${nodef[@]}" --bin qemu --features "$feat_bench" >&2
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
qemu_out=$(timeout 120 qemu-system-arm -M netduinoplus2 -nographic -monitor none -serial null \
  -semihosting-config enable=on,target=native -icount shift=0 -kernel "$elf_qemu" || true)
line=$(grep '^BENCH' <<<"$qemu_out" || true)
[ -n "$line" ] || { echo "the QEMU benchmark printed no BENCH line" >&2; exit 1; }
get() { sed -n "s/.* $1=\([0-9]*\).*/\1/p" <<<"$line"; }
stack_line=$(grep '^STACK' <<<"$qemu_out" || true)
sget() { sed -n "s/.* $1=\([0-9]*\).*/\1/p" <<<"$stack_line"; }
step_stack_bench=$(sget step); step_stack_stress=$(sget step_stress)
[ -n "$step_stack_bench" ] && [ -n "$step_stack_stress" ] \
  || { echo "the QEMU benchmark printed no STACK line: $stack_line" >&2; exit 1; }
step_stack=$(( step_stack_bench > step_stack_stress ? step_stack_bench : step_stack_stress ))

# The static bound of the measured function, in this ELF (before the cycle estimate rebuilds it).
step_static=""
if command -v python3 >/dev/null && command -v arm-none-eabi-objdump >/dev/null \
    && command -v arm-none-eabi-nm >/dev/null; then
  step_sym=$(arm-none-eabi-nm "$elf_qemu" | awk '$3 ~ /^_ZN4qemu5bench4step17h[0-9a-f]+E$/ {print $3}')
  [ -n "$step_sym" ] || { echo "no bench::step in $elf_qemu" >&2; exit 1; }
  step_static=$(python3 bitcraze-app/stack-estimate.py "$elf_qemu" "$step_sym" \
    | sed -n 's/.*: worst-case stack \([0-9]*\) B$/\1/p')
  [ -n "$step_static" ] || { echo "stack-estimate.py gave no bound for $step_sym" >&2; exit 1; }
elif [ "${CI:-}" = true ]; then
  echo "need python3 and arm-none-eabi-objdump/nm for the step's static stack bound (apt-get install binutils-arm-none-eabi)" >&2
  exit 1
else
  echo "no python3 or arm-none-eabi-objdump: the step's measured stack is not set against its static bound" >&2
fi

# Estimated cycles: a 200-step bench traced instruction by instruction (the same code; only the
# step count differs), then the regular bench is rebuilt by the next run.
cyc_low=""; cyc_mid=""; cyc_high=""; cyc_ins=""
if [ "${CYCLES:-1}" != 0 ]; then
  if command -v python3 >/dev/null && command -v arm-none-eabi-objdump >/dev/null; then
    echo "tracing a 200-step bench for the cycle estimate ..." >&2
    HAMFLIGHT_BENCH_STEPS=200 cargo build --release "${nodef[@]}" --bin qemu --features "$feat_bench" >&2
    cp "$elf_qemu" "$tdir/qemu-trace200"
    tline=$(python3 tools/trace-profile.py --summary "$tdir/qemu-trace200")
    tget() { sed -n "s/.* $1=\([0-9]*\).*/\1/p" <<<"$tline"; }
    cyc_ins=$(tget instructions); cyc_low=$(tget cycles_low); cyc_mid=$(tget cycles_mid); cyc_high=$(tget cycles_high)
  else
    echo "no python3 or arm-none-eabi-objdump: no cycle estimate" >&2
  fi
fi
steps=$(get steps); total=$(get total); max=$(get max); min=$(get min)
peak=$(get stack_peak); boot=$(get stack_boot_peak); ssize=$(get stack_size); blob_len=$(get blob_len)

# SysTick runs on the 168 MHz core clock of QEMU's netduinoplus2; with -icount shift=0 one
# instruction takes 1 ns of virtual time, so instructions = ticks * 1000 / 168.
# Time at 168 MHz assumes one cycle per instruction (Cortex-M4F: most ALU/FPU ops; loads,
# branches, divisions, sqrt and flash wait states cost more, so the real figure is higher;
# measure with the DWT cycle counter on the board: the telemetry's step_cost there is cycles).
# The step's stack budget: the stabilizer task, where hf_step runs inline on the Crazyflie, has
# 1,800 B (STABILIZER_TASK_STACKSIZE). 15 % stays unused: 1,800 - 270 = 1,530 B. Above the step:
# Bitcraze's frames, about 100 B (stabilizerTask 88 + controller 8 in cf2.elf), and our C shim's
# controllerOutOfTree, 32 B; at the deepest point a context switch, 204 B (the FPU exception
# frame 104 + FreeRTOS's saved r4-r11, lr, s16-s31 100). 1,530 - 100 - 32 - 204 = 1,194 B.
step_stack_budget=1194
awk -v steps="$steps" -v total="$total" -v max="$max" -v min="$min" -v flash="$flash" \
    -v sram="$sram" -v peak="$peak" -v boot="$boot" -v ssize="$ssize" -v blob="$blob_len" \
    -v sstep="$step_stack" -v sbench="$step_stack_bench" -v sstress="$step_stack_stress" \
    -v sstatic="$step_static" -v sbudget="$step_stack_budget" \
    -v features="${extra:-default}${nodef[*]:+ (no default features: gradient law)}" -v cins="$cyc_ins" \
    -v clow="$cyc_low" -v cmid="$cyc_mid" -v chigh="$cyc_high" -v kv="${REPORT_KV:-}" '
function ins(t) { return t * 1000.0 / 168.0 }
BEGIN {
  mean = ins(total / steps)
  step_budget = 10000; flash_budget = 64 * 1024; sram_budget = 32 * 1024
  printf "| quantity (features: %s) | value | budget |\n| --- | --- | --- |\n", features
  printf "| control step, mean (%d steps) | %.0f instructions (%.1f us at 168 MHz, 1 instruction/cycle) | %s |\n", steps, mean, mean/168, "<= 10,000 instructions"
  printf "| control step, max | %.0f instructions (%.1f us) | |\n", ins(max), ins(max)/168
  printf "| control step, min | %.0f instructions (%.1f us) | |\n", ins(min), ins(min)/168
  if (cmid != "")
    printf "| control step, estimated Cortex-M4F cycles (first 200 steps, %s instructions) | %s (%s-%s; %.1f us at 168 MHz, zero wait states) | |\n", cins, cmid, clow, chigh, cmid/168
  printf "| flash (Crazyflie build, incl. %s-byte weight blob) | %d bytes (%.1f KiB) | <= 64 KiB |\n", blob, flash, flash/1024
  printf "| static RAM (.data + .bss + .uninit) | %d bytes (%.1f KiB) | <= 32 KiB |\n", sram, sram/1024
  printf "| peak stack, running (control loop + interrupts) | %d bytes | |\n", peak
  printf "| peak stack, boot (blob check, in-place decode) | %d bytes (of %d free) | |\n", boot, ssize
  printf "| control step stack, measured high-water (painted; bench flight %d, off-nominal cases %d) | %d bytes (static bound: %s) | <= %d bytes |\n", sbench, sstress, sstep, (sstatic == "" ? "not computed" : sstatic " bytes"), sbudget
  over = 0
  if (ins(max) > step_budget) { printf "OVER BUDGET: worst step %.0f > %d instructions\n", ins(max), step_budget > "/dev/stderr"; over = 1 }
  if (flash > flash_budget) { printf "OVER BUDGET: flash %d > %d bytes\n", flash, flash_budget > "/dev/stderr"; over = 1 }
  if (sram > sram_budget) { printf "OVER BUDGET: static RAM %d > %d bytes\n", sram, sram_budget > "/dev/stderr"; over = 1 }
  if (sstep > sbudget) { printf "OVER BUDGET: the control step stack %d > %d bytes\n", sstep, sbudget > "/dev/stderr"; over = 1 }
  if (sstatic != "" && sstep > sstatic + 0) { printf "STACK ESTIMATOR WRONG: the step measured %d bytes, more than the bound of stack-estimate.py, %d bytes\n", sstep, sstatic > "/dev/stderr"; over = 1 }
  if (kv != "")
    printf "mean_instructions=%.0f max_instructions=%.0f min_instructions=%.0f flash_bytes=%d sram_bytes=%d stack_peak_bytes=%d stack_boot_bytes=%d blob_bytes=%d step_stack_bytes=%d%s\n", mean, ins(max), ins(min), flash, sram, peak, boot, blob, sstep, (sstatic == "" ? "" : " step_stack_static_bytes=" sstatic) > kv
  exit over
}'
