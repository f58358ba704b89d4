#!/usr/bin/env bash
# build-in-tree.sh CRAZYFLIE_BASE [MAKE_ARGS...]
#
# Builds crazyflie-firmware (the checkout at CRAZYFLIE_BASE) with hamflight as its out-of-tree
# controller: cf2_defconfig + app-config, into this directory's build/ (build/cf2.bin). The
# checkout itself is not modified. MAKE_ARGS go to make (e.g. HAMFLIGHT_1KHZ=1); JOBS sets -j.
#
# Needs: a crazyflie-firmware git checkout with its submodules (the build runs git rev-parse),
# gcc-arm-none-eabi, and the Rust toolchain of this repository (rust-toolchain.toml).
#
# Before building, it checks that our stand-in Bitcraze headers (host-include/, used by the host
# tests) still have the layout of this checkout's: the same list of sizes and offsets from
# host-include/bitcraze_layout.c compiled against both with arm-none-eabi-gcc.
set -euo pipefail

if [ "$#" -lt 1 ]; then
    echo "usage: $0 CRAZYFLIE_BASE [MAKE_ARGS...]" >&2
    exit 2
fi
base=$(cd "$1" && pwd)
shift
here=$(cd "$(dirname "${BASH_SOURCE[0]}")" && pwd)

[ -f "$base/tools/make/oot.mk" ] || { echo "$base is not a crazyflie-firmware checkout (no tools/make/oot.mk)" >&2; exit 1; }
git -C "$base" rev-parse HEAD >/dev/null 2>&1 || { echo "$base is not a git repository (the firmware build runs git rev-parse)" >&2; exit 1; }
command -v arm-none-eabi-gcc >/dev/null 2>&1 || { echo "arm-none-eabi-gcc not found (apt-get install gcc-arm-none-eabi)" >&2; exit 1; }

echo "== layout of host-include/ against $base"
cflags=(-mcpu=cortex-m4 -mthumb -mfloat-abi=hard -mfpu=fpv4-sp-d16 -std=gnu11 -O0 -S -o -)
real=$(arm-none-eabi-gcc "${cflags[@]}" -I"$base/src/modules/interface" -I"$base/src/hal/interface" \
    -I"$base/src/utils/interface/lighthouse" -I"$base/src/utils/interface" \
    "$here/host-include/bitcraze_layout.c" | grep -E '^[[:space:]]+\.word')
ours=$(arm-none-eabi-gcc "${cflags[@]}" -I"$here/host-include" "$here/host-include/bitcraze_layout.c" \
    | grep -E '^[[:space:]]+\.word')
if [ "$real" != "$ours" ]; then
    echo "host-include/ no longer matches this checkout's stabilizer_types.h:" >&2
    diff <(printf '%s\n' "$real") <(printf '%s\n' "$ours") >&2 || true
    exit 1
fi
echo "same sizes and offsets ($(printf '%s\n' "$real" | wc -l) values)"

echo "== configure (cf2_defconfig + app-config)"
make -C "$here" CRAZYFLIE_BASE="$base" cf2_defconfig
echo "== build"
make -C "$here" CRAZYFLIE_BASE="$base" -j"${JOBS:-$(nproc)}" "$@"
echo "== built $here/build/cf2.bin"

# Stack: the stabilizer task has 1,800 bytes in all (STABILIZER_TASK_STACKSIZE = 450 words), the
# app task CONFIG_APP_STACKSIZE words (app-config), less an FPU exception frame (104 bytes).
echo "== worst-case stack (stack-estimate.py)"
app_words=$(sed -n 's/^CONFIG_APP_STACKSIZE=//p' "$here/app-config")
# controllerOutOfTree runs the core's step inline: 1,200 B leaves the stabilizer task 600 B for
# its own frames (the stock Lee controller reaches about 1,000 B). controllerOutOfTreeInit first
# runs in the system task (1,200 B in all). appMain builds the controller, runs the boot self test
# and the model swaps.
python3 "$here/stack-estimate.py" "$here/build/cf2.elf" controllerOutOfTree=1200 \
    controllerOutOfTreeInit=600 \
    "appMain=$((app_words * 4 - 104 - 200))"
