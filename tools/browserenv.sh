#!/usr/bin/env bash
# The browser the web page's test drives: Debian's chromium (installed with
# apt-get when missing; the test set-up runs as root) and npm's
# playwright-core, pinned, under target/ (made once). Prints the
# node_modules directory on stdout; any failure (no node, no network, no
# root) is one line on stderr and exit 1, so that the test fails loudly
# instead of skipping.
set -euo pipefail
root="$(cd "$(dirname "$0")/.." && pwd)"
version="1.64.1"
dir="${LIGHTPOSE_BROWSERENV:-$root/target/browserenv}"
mkdir -p "$dir"
exec 9>"$dir.lock"
flock 9
if ! command -v node >/dev/null || ! command -v npm >/dev/null; then
    echo "tools/browserenv.sh: node and npm not found: the web page's browser test needs Node.js (apt-get install -y nodejs npm)" >&2
    exit 1
fi
if [ ! -x /usr/bin/chromium ]; then
    if ! apt-get install -y chromium >"$dir/apt.log" 2>&1; then
        echo "tools/browserenv.sh: /usr/bin/chromium missing and apt-get install -y chromium failed (see $dir/apt.log; run as root, after apt-get update)" >&2
        exit 1
    fi
fi
stamp="$dir/node_modules/playwright-core/package.json"
if [ ! -f "$stamp" ] || ! grep -q "\"version\": \"$version\"" "$stamp"; then
    if ! npm install --prefix "$dir" --no-audit --no-fund --no-save "playwright-core@$version" >"$dir/npm.log" 2>&1; then
        echo "tools/browserenv.sh: npm install playwright-core@$version failed (see $dir/npm.log)" >&2
        exit 1
    fi
fi
echo "$dir/node_modules"
