#!/usr/bin/env bash
# Check a built extension image as BlueOS uses it, where docker runs (not
# in CI, which has no docker daemon): its labels (every JSON one parsed,
# `permissions` as Docker's create body with host networking), then the
# container started as BlueOS starts it (host networking, the extension's
# folder bound to /etc/lightpose, which the entrypoint fills the first
# time) on the image's own config, the simulated tank, and from outside:
# GET / is the page, and /register_service, /v1/status, /v1/pose, a 404
# and one live event match config/blueos/openapi.json
# (crates/daemon/tests/web_openapi.py, Python's jsonschema).
#
#   tools/blueos-image-check.sh                 # lightpose/blueos-lightpose:VERSION-linux-amd64
#   tools/blueos-image-check.sh IMAGE [PLATFORM] # another tag; an ARM one needs qemu binfmt (F flag)
#
# The SPI and I2C devices of `permissions` are not passed: the simulated
# tank needs none, and a machine without the boards has none to pass.
set -euo pipefail
cd "$(dirname "$0")/.."
version=$(sed -n 's/^version = "\(.*\)"/\1/p' Cargo.toml | head -1)
img=${1:-lightpose/blueos-lightpose:$version-linux-amd64}
platform=${2:-}
port=17160
py=$(tools/pyenv.sh)
if ! command -v docker >/dev/null || ! docker info >/dev/null 2>&1; then
    echo "blueos-image-check: no docker daemon answers (docker info failed)" >&2
    exit 1
fi

# --- the labels ---------------------------------------------------------------
docker image inspect "$img" --format '{{json .Config.Labels}}' | "$py" -c '
import json, sys
labels = json.load(sys.stdin)
for key in ["permissions", "authors", "company", "links", "tags"]:
    json.loads(labels[key])
perm = json.loads(labels["permissions"])
host = perm["HostConfig"]
assert host["NetworkMode"] == "host", host
assert "17160/tcp" in perm["ExposedPorts"], perm
print("labels: version %s, type %s, requirements %r; permissions: NetworkMode %s, %d devices, binds %s"
      % (labels["version"], labels["type"], labels["requirements"], host["NetworkMode"],
         len(host["Devices"]), host["Binds"]))
'
docker image inspect "$img" --format 'image: {{.Os}}/{{.Architecture}}{{if .Variant}}/{{.Variant}}{{end}}, {{.Size}} bytes'

# --- the container, as BlueOS starts it ----------------------------------------
if "$py" -c "import socket,sys; s=socket.socket(); sys.exit(s.connect_ex(('127.0.0.1', $port)) != 0)"; then
    echo "blueos-image-check: something already listens on port $port; stop it first" >&2
    exit 1
fi
folder=$(mktemp -d)
name="lightpose-check-$$"
trap 'docker rm -f "$name" >/dev/null 2>&1 || true; rm -rf "$folder"' EXIT
run_args=(-d --name "$name" --network host -v "$folder:/etc/lightpose")
if [ -n "$platform" ]; then run_args+=(--platform "$platform"); fi
start=$(date +%s.%N)
docker run "${run_args[@]}" "$img" >/dev/null
for _ in $(seq 1 300); do
    if "$py" -c "import urllib.request; urllib.request.urlopen('http://127.0.0.1:$port/register_service', timeout=1)" 2>/dev/null; then
        break
    fi
    if [ "$(docker inspect -f '{{.State.Running}}' "$name")" != true ]; then
        docker logs "$name" >&2
        echo "blueos-image-check: the container stopped" >&2
        exit 1
    fi
    sleep 0.1
done
"$py" -c "import time; print('answered /register_service %.1f s after docker run' % (time.time() - $start))"
test -f "$folder/lightposed.toml" || { echo "blueos-image-check: the entrypoint wrote no lightposed.toml" >&2; exit 1; }
"$py" - "$port" <<'PY'
import json, sys, time, urllib.request
base = "http://127.0.0.1:%s" % sys.argv[1]
with urllib.request.urlopen(base + "/", timeout=5) as r:
    body = r.read()
    assert r.status == 200 and r.headers["Content-Type"].startswith("text/html"), (r.status, r.headers)
    assert b"app.js" in body
with urllib.request.urlopen(base + "/register_service", timeout=5) as r:
    reg = json.load(r)
assert reg["works_in_relative_paths"] is True, reg
with urllib.request.urlopen(base + "/v1/status", timeout=5) as r:
    st = json.load(r)
# The simulated tank's pose becomes `ok` once the tracker has settled.
deadline = time.time() + 30
while True:
    with urllib.request.urlopen(base + "/v1/pose", timeout=5) as r:
        pose = json.load(r)
    if pose.get("status") == "ok" or time.time() > deadline:
        break
    time.sleep(0.2)
assert pose.get("status") == "ok", pose
with urllib.request.urlopen(base + "/v1/status", timeout=5) as r:
    st = json.load(r)
print("GET / 200 (%d bytes); register_service: %s %s; status: %s frames, %s fps, web %s; pose: %s"
      % (len(body), reg["name"], reg["version"], st["frames"], st["fps"],
         st["web"].get("listen"), pose.get("status")))
PY
"$py" crates/daemon/tests/web_openapi.py config/blueos/openapi.json "http://127.0.0.1:$port"
docker stats --no-stream --format 'container: CPU {{.CPUPerc}}, memory {{.MemUsage}}' "$name"
echo "--- the container's log"
docker logs "$name" 2>&1 | head -20
echo "blueos-image-check: $img ok"
