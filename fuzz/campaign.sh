#!/usr/bin/env bash
# The loaders' fuzz campaign: each target in turn (one fuzzing process at a time), RUNS
# executions each, from the seeds of `fuzz-seeds` and the committed corpus, into a working
# corpus outside the repository. Needs the nightly toolchain and cargo-fuzz.
#
#   fuzz/campaign.sh WORK [RUNS] [TARGET...]      (defaults: 10000000 runs, every target)
#
# WORK/seeds/<target>   seeds (written here by fuzz-seeds when absent)
# WORK/corpus/<target>  the working corpus; WORK/artifacts/<target>/ crashes, timeouts, OOMs
# WORK/logs/<target>.log libFuzzer's output; its last line says how many runs were done.
# Afterwards, fuzz/minimize.sh WORK merges the working corpora into fuzz/corpus.
set -euo pipefail
cd "$(dirname "$0")/.."
work="$(mkdir -p "$1" && cd "$1" && pwd)"
runs="${2:-10000000}"
shift $(( $# >= 2 ? 2 : $# ))
targets=("$@")
[ ${#targets[@]} -gt 0 ] || targets=(obj ply_ascii ply_binary_le ply_binary_be gltf)
models="${OCCULT_MODELS:-$(cd .. && pwd)/shared/models}"
if [ ! -d "$work/seeds" ]; then
  # The test fixtures are the files the loader tests write under target/tmp/occult-loaders.
  nice -n 19 cargo test --release -p occult-scenes --test scenes -- loaders meshopt >/dev/null
  nice -n 19 cargo run --release -p occult-fuzz --bin fuzz-seeds -- "$work/seeds" "$models" target/tmp/occult-loaders
fi
# No sanitizer: the targets are safe Rust but for the meshopt decoder (C++, which fuzz/asan.sh
# covers with AddressSanitizer); 5-10 times the executions per second. Allocations are capped
# by the targets' CappedAllocator (in proportion to the input) and by -rss_limit_mb.
# The binaries are built once and copied to WORK/bin, so that editing the sources while a
# campaign runs changes nothing under it.
# CAMPAIGN_PREBUILT=1 runs the binaries already in WORK/bin. CAMPAIGN_MAX_LEN (default 1024)
# bounds the input size: small inputs reach the header and structure checks where the bugs
# are, at several times the executions per second of 4 KiB inputs.
mkdir -p "$work/logs" "$work/bin"
if [ "${CAMPAIGN_PREBUILT:-0}" != 1 ]; then
  (cd fuzz && nice -n 19 cargo +nightly fuzz build -O -s none)
  for t in "${targets[@]}"; do
    cp "fuzz/target/x86_64-unknown-linux-gnu/release/$t" "$work/bin/$t"
  done
fi
for t in "${targets[@]}"; do
  mkdir -p "$work/corpus/$t" "$work/artifacts/$t"
  cp -n "$work/seeds/$t/"* "$work/corpus/$t/" 2>/dev/null || true
  cp -n fuzz/corpus/"$t"/* "$work/corpus/$t/" 2>/dev/null || true
  nice -n 19 "$work/bin/$t" "$work/corpus/$t" \
     -runs="$runs" -max_len="${CAMPAIGN_MAX_LEN:-1024}" -timeout=10 -rss_limit_mb=2048 -malloc_limit_mb=256 \
     -print_final_stats=1 -artifact_prefix="$work/artifacts/$t/" >"$work/logs/$t.log" 2>&1 \
    || echo "$t: libFuzzer stopped early (see $work/logs/$t.log and $work/artifacts/$t)"
  grep -E '^Done [0-9]+ runs|stat::number_of_executed_units' "$work/logs/$t.log" | sed "s/^/$t: /" || true
done
