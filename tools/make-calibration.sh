#!/bin/sh
# Rebuild config/calibration/tank.toml: the calibration of the default tank
# scene, from the sweeps of MODEL.md (200 frames per pose, as in the paper)
# and a dark log. Deterministic: the seeds are fixed, so a rerun gives the
# same file. crates/pipeline/tests/shipped_calibration.rs checks that the
# shipped file still matches a fresh (reduced) calibration.
set -eu
cd "$(dirname "$0")/.."
cargo build --release -q -p lightpose
L=target/release/lightpose
dir=target/calibration
mkdir -p "$dir"
$L sweep --scene config/scenes/tank.toml --kind all --samples 200 --seed 1 --out "$dir/tank-sweep.jsonl"
# Many dark frames: each offset's error is σ_e/√n (0.05 V/√2000 ≈ 1 mV).
$L sweep --scene config/scenes/tank.toml --kind dark --samples 2000 --seed 2 --out "$dir/tank-dark.jsonl"
$L calibrate --sweep "$dir/tank-sweep.jsonl" --dark "$dir/tank-dark.jsonl" --out config/calibration/tank.toml
