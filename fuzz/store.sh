#!/usr/bin/env bash
# Store a small corpus for the replay test: minimize fuzz/work/T (cargo fuzz cmin), keep its
# smallest files up to BUDGET bytes (default 300000), minimize again, replace fuzz/corpus/T.
set -euo pipefail
cd "$(dirname "$0")"
BUDGET=${BUDGET:-300000}
for t in "$@"; do
  tmp=$(mktemp -d)
  cp -r "work/$t" "$tmp/all"
  opts=(-- -rss_limit_mb=2048 -malloc_limit_mb=512 -timeout=5)
  nice -n 19 cargo +nightly fuzz cmin "$t" "$tmp/all" "${opts[@]}" > "$tmp/cmin1.log" 2>&1
  mkdir "$tmp/small"
  find "$tmp/all" -type f -printf '%s %p\n' | sort -n | awk -v b="$BUDGET" '{s+=$1; if (s>b) exit; print $2}' |
    xargs -r cp -t "$tmp/small"
  nice -n 19 cargo +nightly fuzz cmin "$t" "$tmp/small" "${opts[@]}" > "$tmp/cmin2.log" 2>&1
  rm -rf "corpus/$t" && cp -r "$tmp/small" "corpus/$t"
  echo "$t: $(ls "corpus/$t" | wc -l) files, $(cat corpus/$t/* | wc -c) bytes" \
    "(cmin of all: $(ls "$tmp/all" | wc -l) files)"
  rm -rf "$tmp"
done
