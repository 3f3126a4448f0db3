#!/usr/bin/env bash
# Build lightposed for the vehicle's ARM boards (armv7: Raspberry Pi 2/3 and
# BeagleBone, 32-bit OS; aarch64: Pi 3/4/5 and Jetson, 64-bit OS) and prove
# the armv7 binary runs: under qemu-user it prints --version, records a short
# simulated run and replays that recording to the end.
#
# Installs what it needs (cross gcc, qemu-user, rust targets) and does
# nothing for what is already there, so it can run again at any time.
#
#   tools/cross-build.sh            # both targets + armv7 smoke test
#   CROSS_TARGETS=aarch64-unknown-linux-gnu tools/cross-build.sh
#   CROSS_TARGETS="... x86_64-unknown-linux-gnu" (the host named: tools/blueos-image.sh)
#   CROSS_CHECK_ONLY=aarch64-unknown-linux-gnu tools/cross-build.sh
#   CROSS_BENCH=0 tools/cross-build.sh   # skip the --bench under qemu
#       # type-check that target instead of building it (CI: the armv7
#       # build is the one run under qemu; building both took 4.3 of CI's
#       # 16.6 minutes)
set -euo pipefail
cd "$(dirname "$0")/.."

TARGETS=${CROSS_TARGETS:-"armv7-unknown-linux-gnueabihf aarch64-unknown-linux-gnu"}
SUDO=""
if [ "$(id -u)" != 0 ]; then SUDO="sudo"; fi
# Without a terminal (CI's background job) sudo must not wait for a
# password nobody can type: it fails at once, saying why.
if [ -n "$SUDO" ] && [ ! -t 0 ]; then SUDO="sudo -n"; fi

# --- host packages (Debian/Ubuntu) -----------------------------------------
pkgs=()
have() { command -v "$1" >/dev/null 2>&1; }
have arm-linux-gnueabihf-gcc || pkgs+=(gcc-arm-linux-gnueabihf libc6-dev-armhf-cross)
have aarch64-linux-gnu-gcc || pkgs+=(gcc-aarch64-linux-gnu libc6-dev-arm64-cross)
have qemu-arm || pkgs+=(qemu-user)
if [ ${#pkgs[@]} -gt 0 ]; then
    echo "cross-build: installing ${pkgs[*]}"
    $SUDO apt-get update -qq
    DEBIAN_FRONTEND=noninteractive $SUDO apt-get install -y -qq --no-install-recommends "${pkgs[@]}"
fi

# --- rust targets ------------------------------------------------------------
installed=$(rustup target list --installed)
for t in $TARGETS; do
    grep -qx "$t" <<<"$installed" || rustup target add "$t"
done

# --- build ------------------------------------------------------------------
# Linkers come from .cargo/config.toml; the env vars make the script work
# from a checkout without it as well.
export CARGO_TARGET_ARMV7_UNKNOWN_LINUX_GNUEABIHF_LINKER=arm-linux-gnueabihf-gcc
export CARGO_TARGET_AARCH64_UNKNOWN_LINUX_GNU_LINKER=aarch64-linux-gnu-gcc
# One cargo invocation for every target: cargo schedules their crates
# together, so both cores stay busy.
CHECK_ONLY=${CROSS_CHECK_ONLY:-}
build_args=()
check_args=()
built=()
for t in $TARGETS; do
    case " $CHECK_ONLY " in
    *" $t "*) check_args+=(--target "$t") ;;
    *) build_args+=(--target "$t"); built+=("$t") ;;
    esac
done
if [ ${#build_args[@]} -gt 0 ]; then
    echo "cross-build: building ${built[*]}"
    cargo build --release -p lightposed "${build_args[@]}"
fi
if [ ${#check_args[@]} -gt 0 ]; then
    echo "cross-build: checking $CHECK_ONLY"
    cargo check --release -p lightposed "${check_args[@]}"
fi
out=${CARGO_TARGET_DIR:-target}
for t in "${built[@]}"; do
    file "$out/$t/release/lightposed" 2>/dev/null || ls -l "$out/$t/release/lightposed"
done

# --- armv7 smoke test under qemu-user ---------------------------------------
case " ${built[*]} " in *" armv7-unknown-linux-gnueabihf "*) ;; *) exit 0 ;; esac
BIN=$out/armv7-unknown-linux-gnueabihf/release/lightposed
run() { qemu-arm -L /usr/arm-linux-gnueabihf "$BIN" "$@"; }

run --version
work=$(mktemp -d)
trap 'rm -rf "$work"' EXIT
root=$(pwd)
cat >"$work/record.toml" <<TOML
rate_hz = 50.0
calibration = "$root/config/calibration/tank.toml"
[backend]
kind = "sim"
scene = "$root/config/scenes/tank.toml"
trajectory = "$root/config/trajectories/zigzag.csv"
loop = false
pace = "fast"
[outputs]
destinations = ["127.0.0.1:17159"]
[recording]
dir = "$work/rec"
TOML
run --config "$work/record.toml" 2>"$work/record.log" || { cat "$work/record.log"; exit 1; }
log=$(ls "$work"/rec/*.jsonl)
frames=$(grep -c '"class":"FRAME"' "$log")
echo "cross-build: armv7 recorded $frames frames"
cat >"$work/replay.toml" <<TOML
rate_hz = 50.0
calibration = "$root/config/calibration/tank.toml"
[backend]
kind = "replay"
log = "$log"
pace = "fast"
[outputs]
destinations = ["127.0.0.1:17159"]
TOML
run --config "$work/replay.toml" 2>"$work/replay.log" || { cat "$work/replay.log"; exit 1; }
grep -q "source ended after $frames frames" "$work/replay.log" || {
    cat "$work/replay.log"
    echo "cross-build: armv7 replay did not go through all $frames frames" >&2
    exit 1
}
echo "cross-build: armv7 replay of $frames frames ok"
# Its speed under emulation says little of a board's; CI skips it
# (CROSS_BENCH=0), as it costs a minute or more there.
if [ "${CROSS_BENCH:-1}" != 0 ]; then
    run --bench --frames 2000 --config "$work/record.toml"
fi
