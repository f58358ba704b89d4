#!/usr/bin/env bash
# Regenerates the docs' Bitcraze tables from a crazyflie-firmware checkout: builds bitcraze-loop
# against $CRAZYFLIE_BASE (configured with `make cf2_defconfig && make prepare`), flies the study
# with Bitcraze's Kalman estimate and with the true state, writes their scores to
# docs/data/bitcraze-loop.json and docs/data/bitcraze-loop-truth.json, and rewrites the pages'
# generated blocks from them (doc_tables). CI has no checkout: it checks the pages against these
# committed files (`doc_tables --check`). Run from anywhere; commit docs/data and the pages.
#
#   CRAZYFLIE_BASE=/path/to/crazyflie-firmware tools/bitcraze-loop/doc-data.sh
set -euo pipefail
cd "$(dirname "$0")/../.."
: "${CRAZYFLIE_BASE:?set CRAZYFLIE_BASE to a configured crazyflie-firmware checkout}"
target="${CARGO_TARGET_DIR:-target}"
cargo build --release -p bitcraze-loop
"$target/release/bitcraze-loop" --scores docs/data/bitcraze-loop.json
"$target/release/bitcraze-loop" --state truth --scores docs/data/bitcraze-loop-truth.json
cargo run --release -p host-train --example doc_tables -- --write
