#!/usr/bin/env bash
# The renderer's checks for a machine with a GPU, in one run (about six
# minutes on an H200): `bench raycast` with rays in a compute pass and from
# hull fragments at 1280×1024, flights with rays in a compute pass — SSE,
# and under a frame budget at half the SSE flight's median GPU time — their
# budget table, and 1,000 frames for memory. The flights hold each frame
# for HOLD_MS (default 250) of repeated renders: an H200 idling while the
# CPU loads the next frame's tiles drops from 1,980 to 345 MHz, and
# nvidia-smi's clock log (clocks.csv, if there is nvidia-smi) shows it.
# Everything lands in OUT (default /tmp/sylva-gpu). SYLVA names the binary
# (default target/release/sylva); rmnp's data must lie in ../shared/data/rmnp.
# SMALL=1 runs a quick version (320×256, a few frames) anywhere.
set -uo pipefail
cd "$(dirname "$0")/.."
sylva=$(realpath "${SYLVA:-target/release/sylva}")
out=${OUT:-/tmp/sylva-gpu}
mkdir -p "$out"
export XDG_RUNTIME_DIR=${XDG_RUNTIME_DIR:-/tmp}
size=1280x1024 frames=100 memory=1000 only=() hold=${HOLD_MS:-250}
if [ -n "${SMALL:-}" ]; then
  size=320x256 frames=12 memory=20 only=(--only "exact + 10" --only "linear 30 + 10")
fi
if command -v nvidia-smi >/dev/null; then
  nvidia-smi --query-gpu=timestamp,clocks.sm,pstate,utilization.gpu,power.draw --format=csv -lms 100 \
    >"$out/clocks.csv" 2>&1 &
  trap 'kill %1 2>/dev/null' EXIT
fi
# step SECONDS NAME COMMAND...: runs COMMAND with a time limit, its output in
# OUT/NAME.txt, and says how it ended.
step() {
  local limit=$1 name=$2
  shift 2
  local start=$SECONDS
  timeout "$limit" "$@" >"$out/$name.txt" 2>&1
  echo "== $name: exit $?, $((SECONDS - start)) s"
  tail -n 3 "$out/$name.txt"
}
step 200 raycast-compute "$sylva" bench raycast --size "$size" --ray-pass compute \
  --plot "$out/raycast-compute.png" "${only[@]}"
step 200 raycast-fragment "$sylva" bench raycast --size "$size" --plot "$out/raycast-fragment.png" "${only[@]}"
rmnp=(--config config/examples/rmnp.toml --path config/paths/rmnp_valley.toml)
fly() {
  local limit=$1 name=$2
  shift 2
  step "$limit" "fly-$name" "$sylva" fly "$@" --no-frames --ray-pass compute --hold-ms "$hold" --out "$out/$name" --overwrite
}
fly 60 rmnp-sse "${rmnp[@]}" --frames 30 --size "$size"
budget=$(python3 -c "
import csv, statistics
rows = list(csv.DictReader(open('$out/rmnp-sse/stats.csv')))[3:]
print(round(0.5 * statistics.median(float(r['gpu_ms']) for r in rows), 3))")
echo "budget: $budget ms"
fly 90 rmnp-budget "${rmnp[@]}" --frames "$frames" --size "$size" --lod budget --budget-ms "$budget"
fly 90 demo-budget --path config/paths/demo_valley.toml --frames "$frames" --size "$size" --lod budget \
  --budget-ms "$budget"
step 60 lod-flights "$sylva" bench lod --frames 3 --flights "$out/rmnp-budget" "$out/demo-budget"
hold=0 fly 120 memory --path config/paths/demo_valley.toml --frames "$memory" --size 320x256
