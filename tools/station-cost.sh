#!/bin/sh
# The daemon's CPU with a docking station at 20 Hz, the demodulation on
# (issue 41's goal: under 25 % of one core). Runs lightposed (release) on
# config/examples/dock.toml — the simulator's dock-example at 20 Hz, four
# beacons sampled at 8 kHz, each burst demodulated on the frame thread, the
# tracker on every beacon's image — in real time for SECONDS (default 40)
# after a 5 s start, and reads its CPU from /proc/PID/stat (utime + stime,
# all threads) and per thread from /proc/PID/task/*/stat. The simulator
# making the bursts runs on the frame thread too (a vehicle reads its ADC
# there instead), so `lightposed --bench` on the same config follows: the
# frame thread's parts timed one by one on the source's own bursts.
#
#   tools/station-cost.sh [SECONDS]
set -eu
secs=${1:-40}
cd "$(dirname "$0")/.."
[ -n "${NO_BUILD:-}" ] || cargo build --release -q -p lightposed
D=target/release/lightposed
cfg=config/examples/dock.toml
log=$(mktemp)
$D --config "$cfg" >"$log" 2>&1 &
pid=$!
trap 'kill $pid 2>/dev/null || true; rm -f "$log"' EXIT
sleep 5
tick=$(getconf CLK_TCK)
# utime + stime in ticks: fields 14 and 15 after the command's ")".
cpu() { sed 's/^.*) //' "$1" | awk '{print $12 + $13}'; }
snap() {
    for t in /proc/$pid/task/*; do
        printf '%s\t%s\t%s\n' "${t##*/}" "$(cat "$t/comm")" "$(cpu "$t/stat")"
    done | sort
}
c0=$(cpu /proc/$pid/stat); s0=$(snap); t0=$(date +%s.%N)
sleep "$secs"
c1=$(cpu /proc/$pid/stat); s1=$(snap); t1=$(date +%s.%N)
kill -0 $pid 2>/dev/null || { echo "lightposed ended early:" >&2; cat "$log" >&2; exit 1; }
echo "lightposed --config $cfg, real time, over $(echo "$t1 - $t0" | bc) s (load average $(cut -d' ' -f1-3 /proc/loadavg)):"
echo "| thread | CPU s | % of one core |"
echo "|---|---|---|"
echo "$s0" >"$log.0"; echo "$s1" >"$log.1"
# Threads by id, summed by name; those alive at both ends.
join -t "$(printf '\t')" "$log.0" "$log.1" | awk -F '\t' -v tick="$tick" -v w="$(echo "$t1 - $t0" | bc)" \
    '{d[$2] += ($5 - $3) / tick} END {for (n in d) printf "| %s | %.2f | %.2f |\n", n, d[n], 100 * d[n] / w}' | sort
echo "$c0 $c1 $t0 $t1" | awk -v tick="$tick" \
    '{c = ($2 - $1) / tick; w = $4 - $3; printf "| all (the process) | %.2f | %.2f |\n", c, 100 * c / w}'
rm -f "$log.0" "$log.1"
kill $pid
wait $pid 2>/dev/null || true
echo
$D --bench --frames 2000 --config "$cfg"
