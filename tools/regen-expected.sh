#!/bin/sh
# Rebuild the expected POSE lines of the regression logs in tests/data/
# (X.jsonl -> X.poses.jsonl) with the shipped tank calibration. Run it when
# a change of the pipeline's output is intended, and review the diff.
#
#   tools/regen-expected.sh          expected poses only
#   tools/regen-expected.sh --logs   also re-record the logs themselves
#
# The logs (40-odd frames each): dive and zigzag in the tank (Table 2), the
# dive through a 12-bit ADC, and "hard": an approach into saturation with
# four beacon-off frames spliced in and one garbage line — replayed with
# the paper's method. And, replayed with the tracker (spec v2 readings):
# "fusion-all", the zigzag with attitude, depth and DVL and five bad
# readings spliced in (a negative depth std, a depth 100 m off, a depth
# 3 m off, a DVL at 50 m/s, an attitude std of 0), and "fusion-depth",
# the dive with depth alone.
set -eu
cd "$(dirname "$0")/.."
cargo build --release -q -p lightpose
L=target/release/lightpose
D=tests/data
CAL=config/calibration/tank.toml

if [ "${1:-}" = "--logs" ]; then
    $L simulate --scene config/scenes/tank.toml --trajectory config/trajectories/dive.csv --seed 21 --out $D/dive.jsonl
    $L simulate --scene config/scenes/tank.toml --trajectory config/trajectories/zigzag.csv --seed 22 --out $D/zigzag.jsonl
    $L simulate --scene $D/tank-12bit.toml --trajectory config/trajectories/dive.csv --seed 23 --out $D/dive-12bit.jsonl
    tmp=$(mktemp -d)
    trap 'rm -rf "$tmp"' EXIT
    $L simulate --scene config/scenes/tank.toml --trajectory $D/close.csv --seed 24 --out "$tmp/close.jsonl"
    $L sweep --scene config/scenes/tank.toml --kind dark --samples 4 --seed 25 --out "$tmp/dark.jsonl"
    # Frames 3..6 get the dark frames' counts (the beacon blinked off).
    tail -n +2 "$tmp/dark.jsonl" | jq -c '.counts' > "$tmp/dark-counts"
    {
        head -n 1 "$tmp/close.jsonl"
        tail -n +2 "$tmp/close.jsonl" | jq -c --slurpfile d "$tmp/dark-counts" \
            'if .seq >= 3 and .seq <= 6 then .counts = $d[.seq - 3] else . end'
    } > $D/hard.jsonl
    # One line that is not JSON, after frame 10: replay must name and skip it.
    sed -i '12a this line is not a frame' $D/hard.jsonl
    $L simulate --scene $D/tank-sensors.toml --trajectory config/trajectories/zigzag.csv --seed 26 --out "$tmp/fusion.jsonl"
    {
        head -n 1 "$tmp/fusion.jsonl"
        tail -n +2 "$tmp/fusion.jsonl" | jq -c '
            if .seq == 10 then .depth.std = {z: -0.02}
            elif .seq == 15 then .depth.z += 100
            elif .seq == 20 then .velocity.fwd = 50
            elif .seq == 25 then .depth.z += 3
            elif .seq == 30 then .attitude.std = {pitch: 0, yaw: 1.5}
            else . end'
    } > $D/fusion-all.jsonl
    $L simulate --scene $D/tank-sensors.toml --trajectory config/trajectories/dive.csv --seed 27 --out "$tmp/dive-sensors.jsonl"
    {
        head -n 1 "$tmp/dive-sensors.jsonl"
        tail -n +2 "$tmp/dive-sensors.jsonl" | jq -c 'del(.attitude) | del(.velocity)'
    } > $D/fusion-depth.jsonl
fi

for log in $D/dive.jsonl $D/zigzag.jsonl $D/dive-12bit.jsonl $D/hard.jsonl; do
    $L replay --estimator moments --calibration $CAL --log "$log" --out "${log%.jsonl}.poses.jsonl"
done
for log in $D/fusion-all.jsonl $D/fusion-depth.jsonl; do
    $L replay --estimator tracker --calibration $CAL --log "$log" --out "${log%.jsonl}.poses.jsonl"
done
