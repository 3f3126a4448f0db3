#!/usr/bin/env bash
# The Python the tests use to run independent implementations (the `mcap`
# reader, pymavlink, a WebSocket client): a venv under target/ with the
# pinned packages of tests/python/requirements.txt, made once and remade
# when that file changes. Prints the venv's python on stdout; any failure
# (no python3, no network) is one line on stderr and exit 1, so a test that
# needs it fails loudly instead of skipping.
set -euo pipefail
root="$(cd "$(dirname "$0")/.." && pwd)"
req="$root/tests/python/requirements.txt"
venv="${LIGHTPOSE_PYENV:-$root/target/pyenv}"
stamp="$venv/.requirements"
py3="$(command -v python3 || true)"
if [ -z "$py3" ]; then
    echo "tools/pyenv.sh: python3 not found: the tests against pymavlink and mcap need Python 3 with venv and pip" >&2
    exit 1
fi
# Several test binaries may ask at once: one makes the venv, the others wait.
mkdir -p "$(dirname "$venv")"
exec 9>"$venv.lock"
flock 9
if [ ! -x "$venv/bin/python" ] || ! cmp -s "$req" "$stamp"; then
    rm -rf "$venv"
    if ! "$py3" -m venv "$venv" >"$venv.log" 2>&1; then
        echo "tools/pyenv.sh: python3 -m venv $venv failed (see $venv.log)" >&2
        exit 1
    fi
    if ! "$venv/bin/pip" install --disable-pip-version-check -q -r "$req" >>"$venv.log" 2>&1; then
        echo "tools/pyenv.sh: pip install -r tests/python/requirements.txt failed (see $venv.log)" >&2
        rm -rf "$venv"
        exit 1
    fi
    cp "$req" "$stamp"
fi
echo "$venv/bin/python"
