#!/usr/bin/env bash
# The Python package's CI: a fresh venv, the wheel built by maturin and installed with pip,
# the test dependencies, `pytest python/tests`. Run from anywhere; uses $CARGO_TARGET_DIR (as
# .ci/run sets it) so host-train and burn are compiled once for the root workspace and this.
#   python/ci.sh            # PYTHON=python3.11 to choose the interpreter
set -euo pipefail

cd "$(dirname "${BASH_SOURCE[0]}")/.."
ROOT=$PWD
PYTHON=${PYTHON:-python3}
export CARGO_TARGET_DIR="${CARGO_TARGET_DIR:-$ROOT/target}"
# Recreated fresh every run, at a fixed path: host-train's build script reruns (and host-train
# recompiles) whenever PATH differs from its last build, so the wheel is built without pip's
# build isolation (whose temporary PATH changes every run), with maturin in this venv.
VENV=${HAMFLIGHT_PY_VENV:-$CARGO_TARGET_DIR/python-ci-venv}
export CI=${CI:-true}

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
rm -rf "$VENV"
"$PYTHON" -m venv "$VENV"
# Without build isolation pip runs the build backend from PATH: the venv's maturin.
export PATH="$VENV/bin:$PATH"
"$VENV/bin/python" -m pip install -q --upgrade pip
# pip builds the wheel with maturin (pyproject.toml) and installs it: the README's install line
# (`pip install ./python`), without build isolation for the reason above.
"$VENV/bin/python" -m pip install -q "maturin>=1.9,<2"
"$VENV/bin/python" -m pip install -q --no-build-isolation ./python
lap "wheel built and installed"
# cflib: the optional `crazyflie` extra, for tests/test_crazyflie.py (hamflight-cf).
"$VENV/bin/python" -m pip install -q pytest rotorpy ray cflib
lap "test dependencies installed"

# Run from outside the source tree so the installed package is the one imported.
cd "$ROOT/python/tests"
"$VENV/bin/python" -m pytest -q "$ROOT/python/tests"
lap "pytest passed"
