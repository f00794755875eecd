#!/usr/bin/env bash
# Fuzz the given targets (default: all seven) one after the other, niced, each for SECONDS
# (default 1800) in fork mode so that a crash, hang or OOM is saved and fuzzing goes on.
# Working corpus: fuzz/work/<target>/ (seeded by fuzz/seeds.py, merged with fuzz/corpus/<target>);
# findings: fuzz/artifacts/<target>/; log: fuzz/work/<target>$TAG.log (TAG: optional env, to run
# one target in two processes). Run two of these at once at most.
set -euo pipefail
cd "$(dirname "$0")"
SECONDS_EACH=${SECONDS_EACH:-1800}
targets=("$@")
[ ${#targets[@]} -eq 0 ] && targets=(obj gltf ply toml mgf image solution)
for t in "${targets[@]}"; do
  mkdir -p "work/$t" "corpus/$t" "artifacts/$t"
  echo "$(date -u +%FT%TZ) start $t${TAG:-} (${SECONDS_EACH} s)" >> work/times.log
  nice -n 19 cargo +nightly fuzz run "$t" "work/$t" "corpus/$t" -- \
    -fork=1 -ignore_crashes=1 -ignore_timeouts=1 -ignore_ooms=1 \
    -timeout=1 -rss_limit_mb=2048 -malloc_limit_mb=512 \
    -max_total_time="$SECONDS_EACH" -artifact_prefix="artifacts/$t/" \
    > "work/$t${TAG:-}.log" 2>&1 || echo "$t exited with $?" >> work/times.log
  echo "$(date -u +%FT%TZ) end $t${TAG:-}" >> work/times.log
done
