#!/usr/bin/env bash
# The Python package's CI: the wheel built once by python/build-wheel.sh (abi3, stripped,
# manylinux, the scenarios and weights inside), installed with `pip install WHEEL` into a fresh
# venv (nothing compiles at install time; the install is timed, the installed module's size
# checked), the test extra, `pytest python/tests`. Run from anywhere; uses $CARGO_TARGET_DIR (as
# .ci/run sets it) so host-train and burn are compiled once for the root workspace and this.
#   python/ci.sh            # PYTHON=python3.11 to choose the interpreter
set -euo pipefail

cd "$(dirname "${BASH_SOURCE[0]}")/.."
ROOT=$PWD
PYTHON=${PYTHON:-python3}
export CARGO_TARGET_DIR="${CARGO_TARGET_DIR:-$ROOT/target}"
# The venv the tests run in, recreated every run; the one maturin runs from, kept.
VENV=${HAMFLIGHT_PY_VENV:-$CARGO_TARGET_DIR/python-ci-venv}
BUILD_VENV=${HAMFLIGHT_PY_BUILD_VENV:-$CARGO_TARGET_DIR/python-build-venv}
export CI=${CI:-true}
# The installed native module's limit (a hard failure) and the install time's (reported).
SO_LIMIT_BYTES=$((15 * 1024 * 1024))
INSTALL_LIMIT_S=60

t0=$SECONDS
lap() { printf -- '---- python: %s (%ds)\n' "$1" "$((SECONDS - t0))"; }

# The bridge the equivalence tests compare against. `--workspace --all-targets` is the feature
# set of the README's `cargo test --workspace --release`, so after that step this is a no-op
# (`-p host-train` alone would unify fewer features and recompile burn).
# HAMFLIGHT_HOST_TRAIN=FILE skips this and uses FILE.
if [ -z "${HAMFLIGHT_HOST_TRAIN:-}" ]; then
    cargo build --release --workspace --all-targets
    export HAMFLIGHT_HOST_TRAIN="$CARGO_TARGET_DIR/release/host-train"
fi
lap "host-train built"

# The native module's own lints (python/ is its own cargo workspace, outside the root's).
(cd python && cargo fmt --check && cargo clippy -- -D warnings)
lap "fmt and clippy"

# Debian ships venv apart from python3 (python3-venv); install it when missing, as .ci/run does
# for its own packages.
if ! "$PYTHON" -c "import ensurepip, venv" >/dev/null 2>&1; then
    sudo=()
    [ "$(id -u)" -ne 0 ] && sudo=(sudo)
    "${sudo[@]}" apt-get update
    DEBIAN_FRONTEND=noninteractive "${sudo[@]}" apt-get install -y python3-venv
fi
# maturin, in a venv of its own that is not on PATH: host-train's build script reruns (and
# host-train recompiles) whenever PATH or CI differ from its last build, so the wheel is built
# with this shell's PATH and CI, the root build's above.
if [ ! -x "$BUILD_VENV/bin/maturin" ]; then
    "$PYTHON" -m venv "$BUILD_VENV"
    "$BUILD_VENV/bin/python" -m pip install -q --upgrade pip "maturin>=1.9,<2"
fi
build_start=$SECONDS
WHEEL=$(MATURIN="$BUILD_VENV/bin/maturin" python/build-wheel.sh | tail -n 1)
build_s=$((SECONDS - build_start))
lap "wheel built in ${build_s}s: $(basename "$WHEEL"), $(stat -c %s "$WHEEL") bytes"

# The README's install line, into a fresh venv: the wheel alone (and numpy), timed.
rm -rf "$VENV"
"$PYTHON" -m venv "$VENV"
"$VENV/bin/python" -m pip install -q --upgrade pip
install_start=$(date +%s.%N)
"$VENV/bin/python" -m pip install -q "$WHEEL"
install_s=$(echo "$(date +%s.%N) $install_start" | awk '{printf "%.1f", $1 - $2}')
# Imported from outside the source tree, so the installed package is the one measured.
so=$(cd /tmp && "$VENV/bin/python" -c 'import hamflight._core as c; print(c.__file__)')
so_bytes=$(stat -c %s "$so")
lap "wheel installed in ${install_s}s (limit ${INSTALL_LIMIT_S}s); $(basename "$so"): $so_bytes bytes (limit $SO_LIMIT_BYTES)"
if [ "$so_bytes" -gt "$SO_LIMIT_BYTES" ]; then
    echo "python/ci.sh: the installed $so is $so_bytes bytes, over $SO_LIMIT_BYTES" >&2
    exit 1
fi
if awk -v t="$install_s" -v l="$INSTALL_LIMIT_S" 'BEGIN { exit !(t > l) }'; then
    echo "python/ci.sh: warning: installing the wheel took ${install_s}s, over ${INSTALL_LIMIT_S}s" >&2
fi

# The test extra: pytest, rotorpy, ray, cflib (pure Python; nothing compiles).
"$VENV/bin/python" -m pip install -q "$WHEEL[test]"
lap "test dependencies installed"

# Run from outside the source tree so the installed package is the one imported;
# tests/test_wheel.py checks the wheel HAMFLIGHT_WHEEL names.
cd "$ROOT/python/tests"
HAMFLIGHT_WHEEL="$WHEEL" PATH="$VENV/bin:$PATH" "$VENV/bin/python" -m pytest -q "$ROOT/python/tests"
lap "pytest passed (wheel: build ${build_s}s, install ${install_s}s, module $so_bytes bytes)"
