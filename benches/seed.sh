#!/usr/bin/env bash
# The seeding benchmark of issue 5 in one sitting: installs and starts the
# peers of ../shared/peers (MapServer behind lighttpd as MapProxy's source),
# runs `mapproxy-seed -c 2` over the RMNP DEM's box at Web Mercator levels
# 3-15 (512-px tiles: the resolutions of World Wind levels 0-12, ~1.9 m at
# the finest), counts the tiles it wrote, then runs `sylva bench seed` with
# MapProxy's rate for the ratio. The machine is shared and noisy: only ratios
# from one run are comparable.
set -euo pipefail
cd "$(dirname "$0")/.."
peers=$(cd ../shared/peers && pwd)
work=${PEERS_TMP:-/tmp/peers}
[ -x "$(command -v mapserv)" ] || bash "$peers/setup_mapserver.sh" >/dev/null
[ -x "$work/venv-mapproxy/bin/mapproxy-seed" ] || bash "$peers/setup_mapproxy.sh" >/dev/null
[ -f "$work/data/rmnp-dem.cog.tif" ] || bash "$peers/setup_data.sh" >/dev/null
trap 'bash "$peers/stop_all.sh" >/dev/null 2>&1 || true' EXIT
bash "$peers/stop_all.sh" >/dev/null 2>&1 || true
bash "$peers/run_mapserver.sh"
# The peers' seed.yaml with the levels of this benchmark.
sed -e 's/from: 8/from: 3/' -e 's/to: 13/to: 15/' "$peers/seed.yaml" > "$work/seed-bench.yaml"
rm -rf "$work/mapproxy_cache/c_rmnp_EPSG3857"
t0=$(date +%s.%N)
(cd "$peers" && "$work/venv-mapproxy/bin/mapproxy-seed" -f mapproxy.yaml -s "$work/seed-bench.yaml" -c 2 --seed rmnp_seed) > "$work/logs/seed-bench.log" 2>&1
t1=$(date +%s.%N)
n=$(find "$work/mapproxy_cache/c_rmnp_EPSG3857" -name '*.png' | wc -l)
rate=$(python3 -c "print(round($n / ($t1 - $t0), 1))")
echo "mapproxy-seed -c 2, rmnp bbox, levels 3-15: $n tiles in $(python3 -c "print(round($t1 - $t0, 1))") s = $rate tiles/s"
cargo build --release --quiet
./target/release/sylva bench seed --mapproxy-rate "$rate" | tee "$work/sylva-seed.txt"
