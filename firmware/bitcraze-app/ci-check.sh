#!/usr/bin/env bash
# ci-check.sh: the embedded build of the Crazyflie library, checked the way the firmware will
# link it. Called from .ci/run; runs from anywhere.
#   1. cargo builds libhamflight_bitcraze.a for thumbv7em-none-eabihf (profile `bitcraze`), and
#      clippy checks that build (the panic handler exists only there);
#   2. rust-object.sh turns it into hamflight_rust.o, the object the app's Kbuild links;
#   3. hard-float ABI: `readelf -A` of the object says Tag_ABI_VFP_args: VFP registers, and no
#      member of the archive uses another float-argument convention (Bitcraze compiles with
#      -mfloat-abi=hard -mfpu=fpv4-sp-d16; a soft-float object would not link);
#   4. `nm -u`: every undefined symbol is in firmware-provides.txt;
#   5. no panic formatting, no std/alloc: no core::fmt, panic_fmt, std::, alloc:: symbols;
#   6. sizes (arm-none-eabi-size): data and bss are 0 (the controller's state lives in the C
#      shim's storage), text under TEXT_BUDGET bytes;
#   7. the worst-case stack of hf_step (the core's step with the composite law), from the object
#      alone (linked with ld, then stack-estimate.py), under STEP_STACK_BUDGET bytes;
#   8. the worst-case stack of controllerOutOfTree, which runs hf_step inline in Bitcraze's
#      stabilizer task, under OOT_STACK_BUDGET bytes (1,200: the task has 1,800 in all), of
#      controllerOutOfTreeInit (the system task's 1,200 B) and of appMain (the app task): the shim
#      compiled for the MCU with arm-none-eabi-gcc against host-include/ (whose layout
#      build-in-tree.sh checks against Bitcraze's headers), linked with the Rust object.
#      Bitcraze's own callees (the supervisor queries) are not in this link; build-in-tree.sh
#      measures the same function in the linked cf2.elf. Without the compiler this step fails
#      under CI=true and is skipped, with a message, elsewhere.
#   9. the run-time high-water marks of the entry points (hf_step under both laws, hf_self_test,
#      hf_use_model, hf_model_load, hf_init, hf_blob_check) on a Cortex-M4F under QEMU
#      (qemu-stack.sh: the object of step 2 in a bare-metal harness), each at most its static
#      bound from stack-estimate.py. Without QEMU or the compiler: as step 8.
set -euo pipefail

here=$(cd "$(dirname "${BASH_SOURCE[0]}")" && pwd)
repo=$(cd "$here/../.." && pwd)
target=thumbv7em-none-eabihf
target_dir=${CARGO_TARGET_DIR:-$repo/target}
lib=$target_dir/$target/bitcraze/libhamflight_bitcraze.a
out_dir=$target_dir/bitcraze-app
obj=$out_dir/hamflight_rust.o
# About 1.7x the measured 43.5 KB (of which the weights are 9.7 KB).
TEXT_BUDGET=${TEXT_BUDGET:-75000}
# hf_step's static worst case (1,152 B) plus a little: a step that grows its stack fails here.
STEP_STACK_BUDGET=${STEP_STACK_BUDGET:-1160}
# What the step may take of the stabilizer task's 1,800 B when it runs inline (static worst case: 1,184 B).
OOT_STACK_BUDGET=${OOT_STACK_BUDGET:-1200}

fail() {
    echo "ci-check: FAIL: $*" >&2
    exit 1
}

for tool in arm-none-eabi-ld arm-none-eabi-objcopy arm-none-eabi-nm arm-none-eabi-readelf arm-none-eabi-size arm-none-eabi-objdump; do
    command -v "$tool" >/dev/null 2>&1 || fail "$tool not found (apt-get install binutils-arm-none-eabi)"
done
command -v python3 >/dev/null 2>&1 || fail "python3 not found (apt-get install python3)"

(cd "$repo" && cargo build -p hamflight-bitcraze --profile bitcraze --target "$target" \
    && cargo clippy -p hamflight-bitcraze --profile bitcraze --target "$target" -- -D warnings)
mkdir -p "$out_dir"
"$here/rust-object.sh" "$lib" "$here/hamflight.syms" "$obj"

# 3. hard-float ABI.
attrs=$(arm-none-eabi-readelf -A "$obj")
grep -q "Tag_ABI_VFP_args: VFP registers" <<<"$attrs" || fail "$obj does not use the VFP register ABI:
$attrs"
other=$(arm-none-eabi-readelf -A "$lib" 2>/dev/null | grep "Tag_ABI_VFP_args" | grep -v "VFP registers\|compatible" || true)
[ -z "$other" ] || fail "archive members with another float ABI: $other"
echo "hard-float ABI: Tag_ABI_VFP_args: VFP registers"

# 4. undefined symbols.
allowed=$(sed -e 's/#.*//' -e '/^[[:space:]]*$/d' "$here/firmware-provides.txt")
undefined=$(arm-none-eabi-nm -u "$obj" | awk '{print $NF}')
for s in $undefined; do
    grep -qx "$s" <<<"$allowed" || fail "undefined symbol $s is not provided by the firmware (firmware-provides.txt)"
done
echo "undefined symbols: ${undefined:-none} (all provided by the firmware)"

# Every global is the API.
globals=$(arm-none-eabi-nm -g --defined-only "$obj" | awk '{print $3}' | sort)
api=$(sed -e 's/#.*//' -e '/^[[:space:]]*$/d' "$here/hamflight.syms" | sort)
[ "$globals" = "$api" ] || fail "global symbols differ from hamflight.syms: $globals"
# And the API is the header's.
for s in $api; do
    grep -q "\b$s(" "$here/include/hamflight.h" || fail "$s is exported but not declared in include/hamflight.h"
done

# 5. no formatting, no std.
forbidden=$(arm-none-eabi-nm -C "$obj" | grep -E "core::fmt|panic_fmt|std::|alloc::|__rust_alloc|rust_begin_unwind|rust_eh_personality" || true)
[ -z "$forbidden" ] || fail "panic formatting or std linked in:
$forbidden"
echo "no core::fmt, panic_fmt, std or alloc symbols"

# 6. sizes.
arm-none-eabi-size "$obj"
read -r text data bss _ <<<"$(arm-none-eabi-size "$obj" | awk 'NR==2 {print $1, $2, $3}')"
[ "$data" -eq 0 ] && [ "$bss" -eq 0 ] || fail "the library has RAM state: data $data, bss $bss"
[ "$text" -le "$TEXT_BUDGET" ] || fail "text $text B over the budget $TEXT_BUDGET B"
echo "hamflight_rust.o: text $text B, data $data B, bss $bss B (budget $TEXT_BUDGET B of text)"

# 7. hf_step's worst-case stack. The relocatable object's calls are relocations; linking it
# (firmware symbols left unresolved, hf_step as the root) gives objdump the call targets.
elf=$out_dir/hamflight_rust_stack.elf
arm-none-eabi-ld --gc-sections -e hf_step -u hf_step --unresolved-symbols=ignore-all -o "$elf" "$obj"
python3 "$here/stack-estimate.py" "$elf" "hf_step=$STEP_STACK_BUDGET" \
    || fail "hf_step's stack is over its budget of $STEP_STACK_BUDGET B (it runs inline in the stabilizer task)"

# 8. controllerOutOfTree's worst-case stack, the shim's frame included.
if command -v arm-none-eabi-gcc >/dev/null 2>&1; then
    shim=$out_dir/hamflight_oot_mcu.o
    # Bitcraze's flags for the M4F; -Os and -O2 give the shim the same 32-byte frame.
    arm-none-eabi-gcc -Os -std=gnu11 -mcpu=cortex-m4 -mthumb -mfloat-abi=hard -mfpu=fpv4-sp-d16 \
        -ffunction-sections -fdata-sections -Wall -Werror \
        -I"$here/host-include" -I"$here/include" -c "$here/hamflight_oot.c" -o "$shim"
    # Each entry point the firmware calls, with the task it runs in and that task's budget
    # (every task keeps 15 % of its stack unused after its frames above ours and 204 B for a
    # context switch at the deepest point: the FPU exception frame, 104 B, and FreeRTOS's saved
    # r4-r11, lr and s16-s31, 100 B): the stabilizer task's step (1,800 B); the first init, in
    # the system task (300 words in all, so half for Bitcraze's frames above it and its printf);
    # the app task (app-config's words); the upload's memory handler, in the memory task (1,200 B,
    # 48 B of its own frames above the handler).
    app_words=$(sed -n 's/^CONFIG_APP_STACKSIZE=//p' "$here/app-config")
    for entry in "controllerOutOfTree=$OOT_STACK_BUDGET" "controllerOutOfTreeInit=600" \
        "appMain=$((app_words * 4 * 85 / 100 - 204))" "upMemWrite=768" "upMemRead=768"; do
        fn=${entry%%=*}
        # The memory handlers are static: linked from the function that registers them.
        case $fn in upMem*) root=controllerOutOfTreeInit ;; *) root=$fn ;; esac
        entry_elf=$out_dir/${fn}_stack.elf
        arm-none-eabi-ld --gc-sections -e "$root" -u "$root" --unresolved-symbols=ignore-all \
            -o "$entry_elf" "$shim" "$obj"
        python3 "$here/stack-estimate.py" "$entry_elf" "$entry" \
            || fail "$fn's stack is over its budget (${entry#*=} B)"
    done
elif [ "${CI:-}" = true ]; then
    fail "arm-none-eabi-gcc not found (apt-get install gcc-arm-none-eabi): needed for controllerOutOfTree's stack"
else
    echo "ci-check: SKIPPED controllerOutOfTree's stack: arm-none-eabi-gcc not found (apt-get install gcc-arm-none-eabi)"
fi

# 9. measured high-water marks under QEMU, against the static bounds.
if command -v arm-none-eabi-gcc >/dev/null 2>&1 && command -v qemu-system-arm >/dev/null 2>&1; then
    "$here/qemu-stack.sh" || fail "a measured stack high-water mark is over its static bound (qemu-stack.sh)"
elif [ "${CI:-}" = true ]; then
    fail "arm-none-eabi-gcc or qemu-system-arm not found: needed for the measured stacks (qemu-stack.sh)"
else
    echo "ci-check: SKIPPED the measured stacks: arm-none-eabi-gcc or qemu-system-arm not found"
fi
