#!/usr/bin/env bash
# Makes sure the thumbv7em-none-eabihf standard library is installed for the firmware's
# toolchain. rustup adds rust-toolchain.toml's targets only when it installs the toolchain
# itself; on a machine where 1.95.0 was already there, `cargo build` fails with "can't find crate
# for `core`". Sourced by report.sh; run from anywhere.
set -euo pipefail
target=thumbv7em-none-eabihf
cd "$(dirname "${BASH_SOURCE[0]}")/.."   # firmware/: its rust-toolchain.toml picks the toolchain
if command -v rustup >/dev/null 2>&1; then
  if ! rustup target list --installed | grep -qx "$target"; then
    echo "the $target target is missing: rustup target add $target" >&2
    rustup target add "$target" >&2
  fi
elif [ ! -d "$(rustc --print target-libdir --target "$target")" ]; then
  echo "the $target standard library is missing and there is no rustup to add it;" \
       "install it for $(rustc --version) (e.g. rustup target add $target)" >&2
  exit 1
fi
