#!/usr/bin/env bash
# `sylva cache usage` and `sylva cache prune --max-size` on a synthetic
# directory cache of FILES tiles (default 201,600: 2,000-byte files whose
# times are spread over 30 days), against `du` and `find -delete` on the same
# files: wall time and peak resident memory of each.
#   bash benches/cache_prune.sh [FILES]
set -euo pipefail
cd "$(dirname "$0")/.."
files=${1:-201600}
sylva=${SYLVA:-target/release/sylva}
[ -x "$sylva" ] || cargo build --release --quiet
work=$(mktemp -d)
trap 'rm -rf "$work"' EXIT

make_cache() {
  rm -rf "$work/cache"
  python3 - "$work/cache/v00000000000000aa/cem" "$files" <<'PY'
import os, random, sys, time
root, n = sys.argv[1], int(sys.argv[2])
random.seed(1)
now = time.time()
for i in range(n):
    level, row, col = 8 + i // 25200, (i // 420) % 60, i % 420
    d = f"{root}/{level}/{row}"
    if col == 0:
        os.makedirs(d, exist_ok=True)
    p = f"{d}/{row}_{col}.bil"
    with open(p, "wb") as f:
        f.write(b"\0" * 2000)
    t = now - random.uniform(0, 30 * 86400)
    os.utime(p, (t, t))
PY
  sync
}

timed() {
  local name=$1; shift
  /usr/bin/time -f "$name	%e s	%M KiB" "$@" > /dev/null
}

make_cache
half=$(( $(du -sB1 "$work/cache/v00000000000000aa" | cut -f1) / 2 ))
echo "$files files; times: wall, peak resident memory"
timed "du -s" du -sB1 "$work/cache"
timed "sylva cache usage" "$sylva" cache usage --cache-dir "$work/cache"
timed "prune --dry-run" "$sylva" cache prune --cache-dir "$work/cache" --max-size "$half" --dry-run
timed "prune --max-size (half)" "$sylva" cache prune --cache-dir "$work/cache" --max-size "$half"
make_cache
timed "find -mtime +15 -delete (half)" find "$work/cache" -type f -mtime +15 -delete
