#!/bin/sh
# Regenerate docs/estimators.md's plots: the tracker's Monte Carlo bands
# (2000 runs) on the paper's dive and tank zigzag, without and with the
# attitude sensor, and the trade table (lightpose bench). Deterministic:
# every seed is fixed; only the µs/frame column depends on the machine.
#
#   tools/estimator-plots.sh            # plots and table
#   NO_TABLE=1 tools/estimator-plots.sh # plots only
set -eu
cd "$(dirname "$0")/.."
cargo build --release -q -p lightpose
L=target/release/lightpose
out=target/estimators
mkdir -p "$out" docs/img

run() { # name scene trajectory
    $L montecarlo --scene "$2" --trajectory "$3" --calibration config/calibration/tank.toml \
        --runs 2000 --estimator tracker --seed 1 --out "$out/$1"
    cp "$out/$1/montecarlo.png" "docs/img/tracker-$1.png"
}
run dive-no-sensor config/scenes/tank.toml config/trajectories/dive.csv
run dive-sensor config/scenes/tank-ahrs.toml config/trajectories/dive.csv
run zigzag-no-sensor config/scenes/tank.toml config/trajectories/zigzag.csv
run zigzag-sensor config/scenes/tank-ahrs.toml config/trajectories/zigzag.csv
if [ -z "${NO_TABLE:-}" ]; then
    $L bench --runs 2000 --out "$out/bench.md"
fi
