#!/usr/bin/env bash
# Regenerates the docs' vehicle tables: runs `host-train vehicle-study --seeds 3
# --no-lag-comparison` on the heavy, light and asym vehicles (each logs eight flights, trains
# three blobs and flies both laws on the vehicle's three scenarios), writes their scores to
# docs/data/vehicle-study-{heavy,light,asym}.json, and rewrites the pages' generated blocks from
# them (doc_tables). Too long for every CI run: CI checks the pages against these committed files
# (`doc_tables --check`). Run from anywhere; commit docs/data and the pages.
#
#   tools/vehicle-study-doc-data.sh
set -euo pipefail
cd "$(dirname "$0")/.."
target="${CARGO_TARGET_DIR:-target}"
cargo build --release -p host-train
out="$(mktemp -d)"
for v in heavy light asym; do
    "$target/release/host-train" vehicle-study --vehicle "$v" --seeds 3 --no-lag-comparison --quiet \
        --out "$out/$v" --scores "docs/data/vehicle-study-$v.json"
done
rm -rf "$out"
cargo run --release -p host-train --example doc_tables -- --write
