#!/bin/sh
# rust-object.sh LIB SYMS OUT
#
# Turns the Rust static library LIB (libhamflight_bitcraze.a, thumbv7em-none-eabihf) into one
# relocatable object OUT that Bitcraze's Kbuild links like any C object:
#   1. `ld -r --gc-sections -u <api>`: only what the C API reaches (the core, the weights,
#      libm, the compiler_builtins routines it calls) is kept, however large the archive is;
#   2. `objcopy --keep-global-symbols`: every symbol but the API in SYMS becomes local, so
#      nothing of Rust's (memcpy, __aeabi_* of compiler_builtins, mangled names) can clash with
#      newlib or libgcc in the firmware link; the embedded LLVM bitcode and debug info go.
#      (With LTO the archive is several MB, mostly bitcode; the object is ~44 KB.)
# Bitcraze's Rust proof of concept instead copies the archive as app.o and links it with
# --whole-archive; this keeps the firmware's own link untouched.
#
# CROSS_COMPILE (default arm-none-eabi-) selects the binutils. Fails if an API symbol is missing.
set -eu
if [ "$#" -ne 3 ]; then
    echo "usage: $0 LIB SYMS OUT" >&2
    exit 2
fi
lib=$1
syms=$2
out=$3
cross=${CROSS_COMPILE:-arm-none-eabi-}
[ -f "$lib" ] || { echo "$0: no Rust library at $lib (run the app's make, which builds it)" >&2; exit 1; }
api=$(sed -e 's/#.*//' -e '/^[[:space:]]*$/d' "$syms")
roots=""
for s in $api; do
    roots="$roots -u $s"
done
# shellcheck disable=SC2086 # roots is a list of options
"${cross}ld" -r --gc-sections $roots -o "$out.partial" "$lib"
# .note.GNU-stack goes too: Bitcraze's C objects carry none, and ld warns when it links objects
# with and without it into one built-in.o (the image link sets -z noexecstack itself).
"${cross}objcopy" --keep-global-symbols="$syms" --strip-debug \
    --remove-section=.llvmbc --remove-section=.llvmcmd --remove-section=.note.GNU-stack \
    "$out.partial" "$out.tmp"
rm -f "$out.partial"
defined=$("${cross}nm" -g --defined-only "$out.tmp" | awk '{print $3}')
for s in $api; do
    if ! printf '%s\n' "$defined" | grep -qx "$s"; then
        echo "$0: $s is not defined in $lib" >&2
        rm -f "$out.tmp"
        exit 1
    fi
done
mv "$out.tmp" "$out"
