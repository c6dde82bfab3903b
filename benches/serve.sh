#!/usr/bin/env bash
# The server benchmark of issue 4 in one sitting: installs and starts the
# peers of ../shared/peers (MapServer behind lighttpd, MapProxy in front of
# it), runs `sylva bench serve` (which measures Sylva and the peers with the
# same client and prints the ratios), then `sylva bench soak` for
# SOAK_MINUTES (default 10) on the default configuration, and stops the peers.
# The machine is shared and noisy: only ratios from one run are comparable.
set -euo pipefail
cd "$(dirname "$0")/.."
peers=$(cd ../shared/peers && pwd)
work=${PEERS_TMP:-/tmp/peers}
[ -x "$(command -v mapserv)" ] || bash "$peers/setup_mapserver.sh" >/dev/null
[ -x "$work/venv-mapproxy/bin/gunicorn" ] || bash "$peers/setup_mapproxy.sh" >/dev/null
[ -f "$work/data/rmnp-dem.cog.tif" ] || bash "$peers/setup_data.sh" >/dev/null
trap 'bash "$peers/stop_all.sh" >/dev/null 2>&1 || true' EXIT
bash "$peers/stop_all.sh" >/dev/null 2>&1 || true
bash "$peers/run_mapserver.sh"
rm -rf "$work/mapproxy_cache"
bash "$peers/run_mapproxy.sh"
cargo build --release --quiet
./target/release/sylva bench serve | tee "$work/sylva-serve.txt"
./target/release/sylva bench soak --minutes "${SOAK_MINUTES:-10}" | tee "$work/sylva-soak.txt"
