#!/bin/sh
# Regenerate the tables of docs/extremes.md: what each estimator reports
# across the extremes of issue 8 (crates/pipeline/examples/extremes_table.rs).
# Deterministic (fixed seeds); the prose around the generated block is kept.
set -eu
cd "$(dirname "$0")/.."
cargo run --release -q -p lightpose-pipeline --example extremes_table -- docs/extremes.md
echo "wrote docs/extremes.md"
