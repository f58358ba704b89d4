#!/usr/bin/env bash
# build-in-tree.sh [--platform cf2|cf21bl|all] CRAZYFLIE_BASE [MAKE_ARGS...]
#
# Builds crazyflie-firmware (the checkout at CRAZYFLIE_BASE) with hamflight as its out-of-tree
# controller, for one Bitcraze platform or both, into this directory's build/:
#   cf2     the brushed Crazyflie 2.x (cf2_defconfig + app-config)          -> build/cf2.bin
#   cf21bl  the Crazyflie 2.1 Brushless (cf21bl_defconfig + app-config)    -> build/cf21bl.bin
#   all     both, one after the other
# The default is cf2 (or $PLATFORM). The checkout itself is not modified. MAKE_ARGS go to make
# (e.g. HAMFLIGHT_1KHZ=1); JOBS sets -j (default: nproc). `--help` says more.
#
# Needs: a crazyflie-firmware git checkout with its submodules (the build runs git rev-parse),
# gcc-arm-none-eabi with newlib, python3, and the Rust toolchain of this repository
# (rust-toolchain.toml, with its thumbv7em-none-eabihf target).
#
# Before building, it checks that our stand-in Bitcraze headers (host-include/, used by the host
# tests) still have the layout of this checkout's: the same list of sizes and offsets from
# host-include/bitcraze_layout.c compiled against both with arm-none-eabi-gcc. After each
# build it prints the image's flash and RAM use and the worst-case stack of the tasks that run
# hamflight code.
#
# Both platforms share build/ (Bitcraze's oot.mk fixes KBUILD_OUTPUT to it): their images,
# cf2.* and cf21bl.*, sit side by side, but the objects are those of the last platform built,
# so switching platform recompiles what the configuration changes. `make ... cload` flashes the
# platform configured last.
set -euo pipefail

here=$(cd "$(dirname "${BASH_SOURCE[0]}")" && pwd)
prog=$(basename "$0")

usage() {
    cat <<EOF
usage: $prog [--platform cf2|cf21bl|all] CRAZYFLIE_BASE [MAKE_ARGS...]

Builds Bitcraze's crazyflie-firmware at CRAZYFLIE_BASE with hamflight as its out-of-tree
controller (CONFIG_CONTROLLER_OOT, app-config), into $here/build/.

  --platform P, -p P   cf2     Crazyflie 2.0 / 2.1 / 2.1+ (brushed), cf2_defconfig -> build/cf2.bin
                       cf21bl  Crazyflie 2.1 Brushless, cf21bl_defconfig         -> build/cf21bl.bin
                       all     both, one after the other
                       default: \$PLATFORM if set, else cf2
  -h, --help           this help

  MAKE_ARGS            passed to make: HAMFLIGHT_1KHZ=1 (core at 1 kHz), HAMFLIGHT_WEIGHTS=/abs/x.hfw
                       (another blob; default weights/default.hfw), HAMFLIGHT_UPLOAD=0 (no upload
                       over the radio)
  JOBS=N               make -jN (default: nproc)

Each build ends with its size (flash, RAM and CCM used and free, Bitcraze's size.py) and the
worst-case stack of the stabilizer, system and app tasks' hamflight code; a summary of all
platforms built closes the run. Exit 2: usage; 1: a missing tool, checkout or submodule, a
layout mismatch, a failed build or a stack over budget.

Needs:
  git clone --recursive https://github.com/bitcraze/crazyflie-firmware.git   (cf21bl: 2024 or later)
  sudo apt-get install gcc-arm-none-eabi binutils-arm-none-eabi libnewlib-arm-none-eabi
  rustup target add thumbv7em-none-eabihf   (if the repository's toolchain lacks it)

Flash: cfloader flash build/<platform>.bin stm32-fw -w radio://0/80/2M/E7E7E7E7E7
(docs/crazyflie.md). Flash the image of the vehicle's platform: an image reads the vehicle's
device type at boot and halts on the other platform's (crazyflie-firmware's platformInit).
EOF
}

die() { echo "$prog: $*" >&2; exit 1; }
usage_error() { echo "$prog: $*" >&2; echo "try '$prog --help'" >&2; exit 2; }

platform_arg=${PLATFORM:-cf2}
while [ "$#" -gt 0 ]; do
    case "$1" in
        -h|--help) usage; exit 0 ;;
        -p|--platform)
            [ "$#" -ge 2 ] || usage_error "$1 needs a value: cf2, cf21bl or all"
            platform_arg=$2; shift 2 ;;
        --platform=*) platform_arg=${1#--platform=}; shift ;;
        --) shift; break ;;
        -*) usage_error "unknown option $1" ;;
        *) break ;;
    esac
done
case "$platform_arg" in
    cf2|cf21bl) platforms=("$platform_arg") ;;
    all) platforms=(cf2 cf21bl) ;;
    *) usage_error "unknown platform '$platform_arg' (cf2, cf21bl or all)" ;;
esac
[ "$#" -ge 1 ] || usage_error "missing CRAZYFLIE_BASE, the crazyflie-firmware checkout"
# The firmware's Makefile names its image after PLATFORM and PROG (`PLATFORM ?= cf2`, `PROG ?=
# $(PLATFORM)`): from the environment or the command line they would misname a build.
unset PLATFORM PROG
for arg in "${@:2}"; do
    case "$arg" in
        PLATFORM=*|PROG=*) usage_error "$arg: choose the platform with --platform, not a make variable" ;;
    esac
done

[ -d "$1" ] || die "no such directory: $1 (the crazyflie-firmware checkout: git clone --recursive https://github.com/bitcraze/crazyflie-firmware.git)"
base=$(cd "$1" && pwd)
shift

# --- the tools ---------------------------------------------------------------------------------
command -v arm-none-eabi-gcc >/dev/null 2>&1 ||
    die "arm-none-eabi-gcc not found; on Debian/Ubuntu: sudo apt-get install gcc-arm-none-eabi binutils-arm-none-eabi libnewlib-arm-none-eabi"
# Bitcraze links with --specs=nano.specs: newlib is a package of its own on Debian.
nano=$(arm-none-eabi-gcc -mcpu=cortex-m4 -mthumb -mfloat-abi=hard -mfpu=fpv4-sp-d16 -print-file-name=nano.specs)
[ -f "$nano" ] ||
    die "arm-none-eabi-gcc has no newlib (nano.specs); on Debian/Ubuntu: sudo apt-get install libnewlib-arm-none-eabi"
for tool in arm-none-eabi-size arm-none-eabi-objdump arm-none-eabi-ld; do
    command -v "$tool" >/dev/null 2>&1 ||
        die "$tool not found; on Debian/Ubuntu: sudo apt-get install binutils-arm-none-eabi"
done
command -v python3 >/dev/null 2>&1 || die "python3 not found (the firmware build and stack-estimate.py need it)"
command -v cargo >/dev/null 2>&1 || die "cargo not found: install Rust (https://rustup.rs); rust-toolchain.toml pins the version"
if command -v rustup >/dev/null 2>&1; then
    (cd "$here" && rustup target list --installed 2>/dev/null) | grep -qx thumbv7em-none-eabihf ||
        die "the Rust target thumbv7em-none-eabihf is not installed: (cd $here && rustup target add thumbv7em-none-eabihf)"
fi

# --- the checkout ------------------------------------------------------------------------------
[ -f "$base/tools/make/oot.mk" ] ||
    die "$base is not a crazyflie-firmware checkout (no tools/make/oot.mk)"
git -C "$base" rev-parse HEAD >/dev/null 2>&1 ||
    die "$base is not a git repository (the firmware build runs git rev-parse): clone it with git"
for f in vendor/FreeRTOS/tasks.c vendor/CMSIS/CMSIS/Core/Include/core_cm4.h \
        vendor/CMSIS/CMSIS/DSP/Source/CommonTables/arm_common_tables.c vendor/libdw1000/src/libdw1000.c; do
    [ -f "$base/$f" ] ||
        die "$base has no $f: its submodules are missing (git -C $base submodule update --init --recursive)"
done
for p in "${platforms[@]}"; do
    [ -f "$base/configs/${p}_defconfig" ] ||
        die "$base has no configs/${p}_defconfig: this checkout does not know the $p platform (the Crazyflie 2.1 Brushless came in 2024; update the checkout)"
done
echo "== crazyflie-firmware $(git -C "$base" rev-parse --short=8 HEAD) at $base; platform(s): ${platforms[*]}"

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

# Bitcraze's size report (tools/make/size.py): both platforms are an STM32F405, 1,008 KB of
# flash for the firmware, 128 KB of RAM, 64 KB of CCM (the firmware's Makefile).
size_report() {
    python3 "$base/tools/make/size.py" arm-none-eabi-size "$1" 1008 128 64
}

app_words=$(sed -n 's/^CONFIG_APP_STACKSIZE=//p' "$here/app-config")
summary=()
for p in "${platforms[@]}"; do
    echo "== $p: configure (${p}_defconfig + app-config)"
    make -C "$here" CRAZYFLIE_BASE="$base" "${p}_defconfig"
    echo "== $p: build"
    make -C "$here" CRAZYFLIE_BASE="$base" -j"${JOBS:-$(nproc)}" "$@"

    # The merged configuration is what flies: the platform asked for, and our app-config.
    config=$here/build/.config
    want=$(echo "$p" | tr '[:lower:]' '[:upper:]')
    for line in "CONFIG_PLATFORM_$want=y" CONFIG_CONTROLLER_OOT=y CONFIG_APP_ENABLE=y; do
        grep -qx "$line" "$config" || die "$p: $config lacks $line after the build (app-config not merged?)"
    done
    [ -f "$here/build/$p.elf" ] || die "$p: the build made no $here/build/$p.elf"
    echo "== $p: built $here/build/$p.bin"

    echo "== $p: size"
    sizes=$(size_report "$here/build/$p.elf")
    printf '%s\n' "$sizes"

    # Stack: the stabilizer task has 1,800 bytes in all (STABILIZER_TASK_STACKSIZE = 450 words,
    # the same on both platforms), the app task CONFIG_APP_STACKSIZE words (app-config), less an
    # FPU exception frame (104 bytes).
    echo "== $p: worst-case stack (stack-estimate.py)"
    # controllerOutOfTree runs the core's step inline: 1,200 B leaves the stabilizer task 600 B
    # for its own frames (the stock Lee controller reaches about 1,000 B).
    # controllerOutOfTreeInit first runs in the system task (1,200 B in all). appMain builds the
    # controller, runs the boot self test and the model swaps.
    # Every task keeps 15 % of its stack after a context switch at the deepest point (204 B: the
    # FPU exception frame and FreeRTOS's saved registers): the app task's budget follows from
    # its words; the memory task (1,200 B, 48 B of its own frames above the handler) runs the
    # upload's handler, COMMIT's blob check included.
    python3 "$here/stack-estimate.py" "$here/build/$p.elf" controllerOutOfTree=1200 \
        controllerOutOfTreeInit=600 \
        "appMain=$((app_words * 4 * 85 / 100 - 204))" upMemWrite=768 upMemRead=768
    summary+=("$p  build/$p.bin" "$(printf '%s\n' "$sizes" | sed 's/^/    /')")
done

echo "== summary (crazyflie-firmware $(git -C "$base" rev-parse --short=8 HEAD))"
printf '%s\n' "${summary[@]}"
