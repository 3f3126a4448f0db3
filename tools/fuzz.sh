#!/usr/bin/env bash
# Coverage-guided fuzzing (libFuzzer via cargo fuzz) of every parser that
# reads outside input: intensity logs (JSONL and MCAP), scene files,
# calibration files, trajectory CSVs, the serial line protocol, the
# daemon's configuration, its ATTITUDE datagrams, the autopilot's MAVLink
# link (serial and UDP) and the DVL's report lines.
#
#   tools/fuzz.sh            # 60 s per target
#   tools/fuzz.sh 3600       # the longer run: an hour per target
#   FUZZ_SANITIZER=none FUZZ_OPT=--dev tools/fuzz.sh 5   # CI: no ASan, dev build
#
# The targets look for panics and broken invariants in safe Rust; ASan
# (the default) also watches the few unsafe lines in dependencies and is
# worth its build time on the long run, not on CI's ten seconds.
#
# cargo fuzz wants nightly flags; RUSTC_BOOTSTRAP lets the stable toolchain
# accept them. A crash leaves its input in fuzz/artifacts/<target>/: turn it
# into a regression test next to the parser's own tests.
set -euo pipefail
cd "$(dirname "$0")/../fuzz"
secs=${1:-60}
command -v cargo-fuzz >/dev/null || cargo install cargo-fuzz --locked
export RUSTC_BOOTSTRAP=1
san=(--sanitizer "${FUZZ_SANITIZER:-address}")
# FUZZ_OPT: -O (optimised, the default: more runs a second) or --dev
# (CI: half the build time for a smoke run of a few seconds).
opt=(${FUZZ_OPT--O})
cargo fuzz build "${opt[@]}" "${san[@]}"
for t in log_reader mcap_reader scene calibration trajectory serial_line daemon_config attitude mavlink_stream dvl_line; do
  mkdir -p "corpus/$t"
  echo "== $t ($secs s)"
  cargo fuzz run "${opt[@]}" "${san[@]}" "$t" "corpus/$t" "seeds/$t" -- -max_total_time="$secs" -rss_limit_mb=2048 2>&1 | grep -E "^(Done|==[0-9]+==|SUMMARY)|panicked" || true
  if ls "artifacts/$t"/crash-* >/dev/null 2>&1; then
    echo "fuzz: $t crashed; inputs in fuzz/artifacts/$t" >&2
    exit 1
  fi
done
echo "fuzz: no crash in $secs s per target"
