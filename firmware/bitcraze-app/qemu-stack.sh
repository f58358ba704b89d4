#!/usr/bin/env bash
# qemu-stack.sh: the MEASURED stack high-water marks of the Crazyflie library's entry points on a
# Cortex-M4F, set against stack-estimate.py's static bounds of the same functions.
#
#   firmware/bitcraze-app/qemu-stack.sh                # the compiled-in and uploaded blob: weights/default.hfw
#   UPLOAD_BLOB=/path/x.hfw firmware/bitcraze-app/qemu-stack.sh   # upload another blob (its port terms)
#
# Builds libhamflight_bitcraze.a (profile `bitcraze`, as ci-check.sh and the app's Makefile do;
# HAMFLIGHT_WEIGHTS picks the compiled-in blob there), turns it into hamflight_rust.o
# (rust-object.sh: the object Bitcraze's build links), links it with qemu-stack/harness.c (bare
# metal, no libc, semihosting) and runs that under QEMU's netduinoplus2. The harness paints the
# stack below each call and reports the deepest word it overwrote (see harness.c for the calls
# and inputs). Then stack-estimate.py bounds each function in the same ELF; the script prints a
# Markdown table and fails when a measured figure exceeds its static bound: the estimator would be
# missing a path, and the budgets that ci-check.sh and build-in-tree.sh hold (static) would not
# bound the run time. The budgets themselves are ci-check.sh's.
#
# Needs qemu-system-arm, arm-none-eabi-gcc and binutils, python3. Called by ci-check.sh.
set -euo pipefail

here=$(cd "$(dirname "${BASH_SOURCE[0]}")" && pwd)
repo=$(cd "$here/../.." && pwd)
target=thumbv7em-none-eabihf
target_dir=${CARGO_TARGET_DIR:-$repo/target}
lib=$target_dir/$target/bitcraze/libhamflight_bitcraze.a
out_dir=$target_dir/bitcraze-app
obj=$out_dir/hamflight_rust.o
elf=$out_dir/qemu-stack.elf
blob=${UPLOAD_BLOB:-${HAMFLIGHT_WEIGHTS:-$repo/weights/default.hfw}}
case $blob in /*) ;; *) blob=$PWD/$blob ;; esac

fail() {
    echo "qemu-stack: FAIL: $*" >&2
    exit 1
}
for tool in qemu-system-arm arm-none-eabi-gcc arm-none-eabi-nm arm-none-eabi-objdump python3; do
    command -v "$tool" >/dev/null 2>&1 || fail "$tool not found (apt-get install qemu-system-arm gcc-arm-none-eabi binutils-arm-none-eabi python3)"
done
[ -f "$blob" ] || fail "no blob at $blob"

(cd "$repo" && cargo build -p hamflight-bitcraze --profile bitcraze --target "$target")
mkdir -p "$out_dir"
"$here/rust-object.sh" "$lib" "$here/hamflight.syms" "$obj"
# Bitcraze's flags for the M4F (as ci-check.sh compiles the shim); no libc, no builtins (the
# copies would call memcpy, which the harness defines itself).
arm-none-eabi-gcc -O2 -std=gnu11 -mcpu=cortex-m4 -mthumb -mfloat-abi=hard -mfpu=fpv4-sp-d16 \
    -ffreestanding -fno-builtin -fno-tree-loop-distribute-patterns -Wall -Wextra -Werror \
    -nostdlib -nostartfiles -T "$here/qemu-stack/harness.ld" -I"$here/include" \
    -DBLOB_PATH="\"$blob\"" "$here/qemu-stack/harness.c" "$here/qemu-stack/blob.S" "$obj" -lgcc \
    -o "$elf"

# SYS_WRITE0 goes to the semihosting console, stderr.
line=$(timeout 120 qemu-system-arm -M netduinoplus2 -nographic -monitor none -serial null \
    -semihosting-config enable=on,target=native -kernel "$elf" 2>&1 || true)
stack=$(grep '^STACK ' <<<"$line" || true)
[ -n "$stack" ] || fail "the harness printed no STACK line: $line"
get() { sed -n "s/.* $1=\([0-9]*\).*/\1/p" <<<"$stack"; }
bound() {
    python3 "$here/stack-estimate.py" "$elf" "$1" | sed -n 's/.*: worst-case stack \([0-9]*\) B$/\1/p'
}

max() { local m=0 v; for v in "$@"; do [ "$v" -gt "$m" ] && m=$v; done; echo "$m"; }
step=$(max "$(get hf_step_gradient)" "$(get hf_step_gradient_stress)" "$(get hf_step_composite)" \
    "$(get hf_step_composite_stress)" "$(get hf_step_uploaded_gradient)" \
    "$(get hf_step_uploaded_gradient_stress)" "$(get hf_step_uploaded_composite)" \
    "$(get hf_step_uploaded_composite_stress)")
use=$(max "$(get hf_use_model)" "$(get hf_use_model_revert)")

echo "| entry point (task) | measured high-water, QEMU Cortex-M4F | static bound (stack-estimate.py, same ELF) |"
echo "| --- | --- | --- |"
over=0
row() {
    local fn=$1 task=$2 measured=$3 detail=$4 static
    static=$(bound "$fn")
    [ -n "$static" ] || fail "stack-estimate.py gave no bound for $fn"
    echo "| \`$fn\` ($task) | $measured B${detail:+ ($detail)} | $static B |"
    if [ "$measured" -gt "$static" ]; then
        echo "qemu-stack: STACK ESTIMATOR WRONG: $fn measured $measured B, more than its static bound $static B" >&2
        over=1
    fi
}
row hf_step "stabilizer" "$step" "flight gradient $(get hf_step_gradient) / composite $(get hf_step_composite), off-nominal $(get hf_step_gradient_stress) / $(get hf_step_composite_stress); uploaded model $(get hf_step_uploaded_gradient) / $(get hf_step_uploaded_composite), off-nominal $(get hf_step_uploaded_gradient_stress) / $(get hf_step_uploaded_composite_stress)"
row hf_self_test "app" "$(get hf_self_test)" ""
row hf_use_model "app" "$use" "upload $(get hf_use_model), revert $(get hf_use_model_revert)"
row hf_model_load "app" "$(get hf_model_load)" ""
row hf_init "app" "$(get hf_init)" ""
row hf_blob_check "memory" "$(get hf_blob_check)" ""
echo "(uploaded blob: $(basename "$blob"), $(wc -c <"$blob") B)"
exit "$over"
