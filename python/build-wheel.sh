#!/usr/bin/env bash
# Builds the hamflight wheel and prints its path (the last line on stdout; maturin's output goes
# to stderr). Run from anywhere:
#
#   python/build-wheel.sh          # -> target/wheels/hamflight-0.1.0-cp39-abi3-manylinux_2_35_x86_64.whl
#   pip install target/wheels/hamflight-0.1.0-cp39-abi3-manylinux_2_35_x86_64.whl
#
# Needs the Rust toolchain and maturin (`pip install 'maturin>=1.9,<2'`; MATURIN=/path/to/maturin
# to choose one). What the wheel is (pyproject.toml, Cargo.toml):
# - one wheel for every CPython >= 3.9 (pyo3's `abi3-py39`: tag cp39-abi3);
# - the native module stripped of symbols and debug info (`strip = true`), about 10 MB;
# - the repository's scenarios/*.toml and weights/default.hfw inside, as hamflight/scenarios and
#   hamflight/weights (symbolic links to the repository's directories in a checkout; maturin
#   copies the files they reach, see `include`);
# - the platform tag is the oldest manylinux policy that maturin's auditwheel check finds the
#   module's glibc symbol versions satisfy. Built on Debian 12 (glibc 2.36) that is
#   manylinux_2_35: libm's hypot@GLIBC_2.35 and libc's pthread_*@GLIBC_2.34 are linked at their
#   newest versions, so the wheel installs on glibc >= 2.35 (Debian 12, Ubuntu 22.04, Fedora 36
#   and later). `--compatibility manylinux_2_28` fails that check here.
#
# Options:
#   --zig GLIBC   link with zig's glibc GLIBC stubs instead (e.g. `--zig 2.17`: manylinux2014,
#                 every glibc >= 2.17). Needs `pip install ziglang`, and cargo then builds for an
#                 explicit --target, in $CARGO_TARGET_DIR/x86_64-unknown-linux-gnu: every
#                 dependency compiles once more (many minutes), so CI does not use it.
#   --out DIR     where the wheel goes (default $CARGO_TARGET_DIR/wheels)
#
# With the shared CARGO_TARGET_DIR (as .ci/run and python/ci.sh set it) the dependencies that the
# root workspace's `cargo build --release --workspace --all-targets` compiled are reused: the
# `strip` flag reaches only the final crate's link (`cargo rustc -- -C strip=symbols`). Run it
# with the PATH and CI of that build: host-train's build script reruns when either changes.
set -euo pipefail

cd "$(dirname "${BASH_SOURCE[0]}")/.."
ROOT=$PWD
export CARGO_TARGET_DIR="${CARGO_TARGET_DIR:-$ROOT/target}"
MATURIN=${MATURIN:-maturin}
OUT="$CARGO_TARGET_DIR/wheels"
ZIG=""

while [ $# -gt 0 ]; do
    case "$1" in
        --zig) ZIG=${2:?--zig needs a glibc version, e.g. 2.17}; shift 2 ;;
        --out) OUT=${2:?--out needs a directory}; shift 2 ;;
        -h|--help) sed -n '2,/^set -euo/p' "${BASH_SOURCE[0]}" | sed '$d; s/^# \{0,1\}//'; exit 0 ;;
        *) echo "build-wheel.sh: unknown argument $1 (see --help)" >&2; exit 2 ;;
    esac
done

if ! command -v "$MATURIN" >/dev/null 2>&1; then
    echo "build-wheel.sh: maturin not found: pip install 'maturin>=1.9,<2' (or set MATURIN)" >&2
    exit 1
fi

args=(build --release -m "$ROOT/python/Cargo.toml" --out "$OUT")
if [ -n "$ZIG" ]; then
    args+=(--zig --compatibility "manylinux_${ZIG//./_}")
fi

# Only this build's wheel in OUT, so the path printed below is the one just built.
mkdir -p "$OUT"
rm -f "$OUT"/hamflight-*.whl
"$MATURIN" "${args[@]}" >&2
wheels=("$OUT"/hamflight-*.whl)
if [ "${#wheels[@]}" -ne 1 ] || [ ! -f "${wheels[0]}" ]; then
    echo "build-wheel.sh: expected one wheel in $OUT, found: ${wheels[*]}" >&2
    exit 1
fi
echo "${wheels[0]}"
