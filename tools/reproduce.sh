#!/bin/sh
# Regenerate docs/reproduction.md's inputs: the harbour calibration (the
# tank one is tools/make-calibration.sh's), the three Monte Carlo cases of
# the paper (section 3.1) with the moments estimator and 2000 runs, and the
# plots under docs/img/. Deterministic: every seed is fixed.
#
#   tools/reproduce.sh            # everything
#   SKIP_CAL=1 tools/reproduce.sh # keep config/calibration/harbour.toml
set -eu
cd "$(dirname "$0")/.."
cargo build --release -q -p lightpose
L=target/release/lightpose
out=target/reproduction
mkdir -p "$out" docs/img

if [ -z "${SKIP_CAL:-}" ]; then
    # The harbour calibration, made exactly as make-calibration.sh makes the
    # tank's, from sweeps in harbour water: each case is calibrated in its
    # own scene (MODEL.md, "Monte Carlo uncertainty").
    dir=target/calibration
    mkdir -p "$dir"
    $L sweep --scene config/scenes/harbour.toml --kind all --samples 200 --seed 1 --out "$dir/harbour-sweep.jsonl"
    $L sweep --scene config/scenes/harbour.toml --kind dark --samples 2000 --seed 2 --out "$dir/harbour-dark.jsonl"
    $L calibrate --sweep "$dir/harbour-sweep.jsonl" --dark "$dir/harbour-dark.jsonl" --out config/calibration/harbour.toml
fi

run() { # name scene trajectory calibration
    $L montecarlo --scene "$2" --trajectory "$3" --calibration "$4" \
        --runs 2000 --estimator moments --seed 1 --out "$out/$1"
    cp "$out/$1/montecarlo.png" "docs/img/montecarlo-$1.png"
}
start=$(date +%s.%N)
run dive-clear config/scenes/tank.toml config/trajectories/dive.csv config/calibration/tank.toml
run zigzag-clear config/scenes/tank.toml config/trajectories/zigzag.csv config/calibration/tank.toml
run zigzag-turbid config/scenes/harbour.toml config/trajectories/zigzag.csv config/calibration/harbour.toml
end=$(date +%s.%N)
echo "three cases, 3 x 2000 realizations: $(echo "$end - $start" | bc) s wall (including writing plots)"
for c in dive-clear zigzag-clear zigzag-turbid; do
    echo; cat "$out/$c/summary.md"
done
