#!/usr/bin/env bash
# Which ROS 2 distro's graph a lightposed build speaks (docs/ros2.md,
# "Distros"): the daemon's default simulation as a ROS 2 node in a private
# network namespace, heard by Cyclone DDS (tests/python/ros2_listener.py)
# as a Humble peer (24-byte GIDs in ros_discovery_info) and as a Jazzy one
# (16). Prints, per peer, the samples heard and the nodes the graph gave.
#   tools/ros2-graph-check.sh [LIGHTPOSED]   (default target/debug/lightposed;
#   the Humble build: cargo build -p lightposed --no-default-features --features humble)
# Needs root (unshare -n) and the test venv (tools/pyenv.sh).
set -euo pipefail
cd "$(dirname "$0")/.."
bin=${1:-target/debug/lightposed}
py=target/pyenv/bin/python
[ -x "$py" ] || { echo "ros2-graph-check: no $py (tools/pyenv.sh makes it)" >&2; exit 1; }
if [ -z "${LIGHTPOSE_IN_NETNS:-}" ]; then
    exec env LIGHTPOSE_IN_NETNS=1 unshare -n "$0" "$bin"
fi
# Discovery multicast stays on this namespace's loopback.
ip link set lo up
ip link set lo multicast on
ip route add 224.0.0.0/4 dev lo
tmp=$(mktemp -d)
trap 'rm -rf "$tmp"' EXIT
{ cat config/lightposed.toml; printf '\n[ros2]\nnetworks = ["127.0.0.1"]\n'; } >"$tmp/cfg.toml"
"$bin" --config "$tmp/cfg.toml" >"$tmp/daemon.log" 2>&1 &
daemon=$!
for gid in 24 16; do
    GID_BYTES=$gid timeout 60 "$py" tests/python/ros2_listener.py 4 >"$tmp/$gid.jsonl" || true
    counts=$(tail -1 "$tmp/$gid.jsonl")
    nodes=$(grep '"topic": "graph"' "$tmp/$gid.jsonl" | head -1 || true)
    echo "peer with ${gid}-byte GIDs: ${counts}; graph: ${nodes:-nothing decoded}"
done
kill "$daemon"
wait "$daemon" || true
grep -m1 "ros2: node" "$tmp/daemon.log" || true
