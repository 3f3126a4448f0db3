#!/bin/sh
# Regenerate docs/estimators.md's plots: the tracker's (auto's) Monte Carlo
# bands (2000 runs) on the paper's dive and tank zigzag with each set of
# the vehicle's own sensors (none, attitude, depth, attitude + depth + DVL),
# and the trade table (lightpose bench, every estimator and sensor set),
# and the open sea's table and plot (lightpose bench --case sea).
# Deterministic: every seed is fixed; only the µs/frame column depends on
# the machine.
#
#   tools/estimator-plots.sh            # plots and table
#   NO_TABLE=1 tools/estimator-plots.sh # plots only
set -eu
cd "$(dirname "$0")/.."
cargo build --release -q -p lightpose
L=target/release/lightpose
out=target/estimators
mkdir -p "$out" docs/img

run() { # name trajectory sensors
    $L montecarlo --scene config/scenes/tank.toml --trajectory "$2" --sensors "$3" \
        --calibration config/calibration/tank.toml \
        --runs 2000 --estimator auto --seed 1 --out "$out/$1"
    cp "$out/$1/montecarlo.png" "docs/img/tracker-$1.png"
}
for traj in dive zigzag; do
    run $traj-no-sensor config/trajectories/$traj.csv none
    run $traj-sensor config/trajectories/$traj.csv attitude
    run $traj-depth config/trajectories/$traj.csv depth
    run $traj-all config/trajectories/$traj.csv all
done
if [ -z "${NO_TABLE:-}" ]; then
    $L bench --runs 2000 --out "$out/bench.md"
fi
# The open sea (spec v3): every estimator, blinking or steady, night or day,
# 200 runs (a blinking run is 2 kHz of samples demodulated); its table
# goes in docs/estimators-bench.md, its plot in docs/img/sea-p95.png.
$L bench --case sea --runs 200 --out "$out/bench-sea.md" --plot docs/img
