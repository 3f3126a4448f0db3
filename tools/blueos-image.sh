#!/usr/bin/env bash
# Build the lightpose BlueOS extension image (config/blueos/Dockerfile) for
# linux/arm/v7, linux/arm64 and linux/amd64 where docker runs (not in CI:
# CI builds the three binaries it holds, BINARIES_ONLY=1). The three come
# from one tools/cross-build.sh run (one cargo invocation for the three
# targets, amd64 named as x86_64-unknown-linux-gnu, so the host's build
# scripts and proc macros are built once; the armv7 one is run under qemu);
# each is stripped and put in target/blueos/bin/<platform>/lightposed, then
# docker buildx builds the three images from them. CARGO_TARGET_DIR is
# honoured (CI's target/ci-cross); the bins always go to target/blueos/bin,
# the Dockerfile's context.
#
#   tools/blueos-image.sh                 # build, tag lightpose/blueos-lightpose:VERSION
#   PUSH=1 tools/blueos-image.sh          # and push (docker login first)
#   BINARIES_ONLY=1 tools/blueos-image.sh # the three binaries, no docker
#   IMAGE_ONLY=1 tools/blueos-image.sh    # the images from the binaries already in target/blueos/bin
#   PLATFORMS=linux/amd64 tools/blueos-image.sh   # fewer platforms (not with PUSH)
set -euo pipefail
cd "$(dirname "$0")/.."
image="lightpose/blueos-lightpose"
version=$(sed -n 's/^version = "\(.*\)"/\1/p' Cargo.toml | head -1)

out=target/blueos/bin
if [ -z "${IMAGE_ONLY:-}" ]; then
    CROSS_BENCH=0 CROSS_TARGETS="armv7-unknown-linux-gnueabihf aarch64-unknown-linux-gnu x86_64-unknown-linux-gnu" tools/cross-build.sh
    built=${CARGO_TARGET_DIR:-target}
    rm -rf "$out"
    for pair in amd64:x86_64-unknown-linux-gnu armv7:armv7-unknown-linux-gnueabihf arm64:aarch64-unknown-linux-gnu; do
        d=${pair%%:*}
        src=$built/${pair#*:}/release/lightposed
        mkdir -p "$out/$d"
        cp "$src" "$out/$d/lightposed"
    done
    strip "$out/amd64/lightposed"
    arm-linux-gnueabihf-strip "$out/armv7/lightposed"
    aarch64-linux-gnu-strip "$out/arm64/lightposed"
fi
ls -l "$out"/*/lightposed
file "$out"/*/lightposed
if [ -n "${BINARIES_ONLY:-}" ]; then
    exit 0
fi
if ! command -v docker >/dev/null; then
    echo "blueos-image: docker not found: the binaries are in $out; build the image where docker runs" >&2
    exit 1
fi
# Without the buildx plugin (Debian's docker.io), the daemon's own BuildKit
# builds one platform at a time into the local store, as --load does.
if docker buildx version >/dev/null 2>&1; then
    build=(docker buildx build)
    load=(--load)
elif [ -z "${PUSH:-}" ]; then
    build=(env DOCKER_BUILDKIT=1 docker build)
    load=()
else
    echo "blueos-image: PUSH needs docker buildx (the three platforms in one manifest)" >&2
    exit 1
fi
# --load takes one platform at a time; a push takes all three at once.
if [ -n "${PUSH:-}" ]; then
    "${build[@]}" --platform linux/arm/v7,linux/arm64,linux/amd64 \
        -f config/blueos/Dockerfile -t "$image:$version" --push .
else
    for p in ${PLATFORMS:-linux/arm/v7 linux/arm64 linux/amd64}; do
        "${build[@]}" --platform "$p" -f config/blueos/Dockerfile \
            -t "$image:$version-${p//\//-}" "${load[@]}" .
    done
fi
