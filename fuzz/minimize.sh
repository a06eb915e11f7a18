#!/usr/bin/env bash
# Minimizes the working corpora of a campaign (fuzz/campaign.sh WORK) into the committed corpus
# fuzz/corpus/<target>/: libFuzzer's -merge=1 keeps the smallest set of inputs that reaches the
# same coverage. Uses the binaries in WORK/bin.
#
#   fuzz/minimize.sh WORK [TARGET...]
set -euo pipefail
cd "$(dirname "$0")/.."
work="$(cd "$1" && pwd)"
shift
targets=("$@")
[ ${#targets[@]} -gt 0 ] || targets=(obj ply_ascii ply_binary_le ply_binary_be gltf)
for t in "${targets[@]}"; do
  fresh="$(mktemp -d)"
  nice -n 19 "$work/bin/$t" -merge=1 -max_len=4096 -timeout=10 -rss_limit_mb=2048 "$fresh" \
    "$work/corpus/$t" fuzz/corpus/"$t" >"$work/logs/$t.merge.log" 2>&1
  rm -rf fuzz/corpus/"$t"
  mv "$fresh" fuzz/corpus/"$t"
  chmod 755 fuzz/corpus/"$t"
  echo "$t: $(ls fuzz/corpus/"$t" | wc -l) inputs, $(du -sk fuzz/corpus/"$t" | cut -f1) KiB"
done
