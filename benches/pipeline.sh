#!/usr/bin/env bash
# `sylva bench pipeline` and the Python baseline (../shared/peers/baseline_pipeline.py:
# the same steps with GDAL + numpy + scipy) in one sitting, then the ratio of
# their median warm tile times. The machine is shared and noisy: only ratios
# from one run are comparable.
set -euo pipefail
cd "$(dirname "$0")/.."
peers=$(cd ../shared/peers && pwd)
work=${PEERS_TMP:-/tmp/peers}
bash "$peers/setup_data.sh" >/dev/null
bash "$peers/setup_baseline.sh" >/dev/null
# The baseline appends to results/ beside itself; run a writable copy.
copy="$work/peers-copy"
rm -rf "$copy" && cp -r "$peers" "$copy" && chmod -R u+w "$copy" && mkdir -p "$copy/results"
cargo build --release --quiet
./target/release/sylva bench pipeline | tee "$work/sylva-pipeline.txt"
DATA=$(cd ../shared/data && pwd) "$work/venv-baseline/bin/python" "$copy/baseline_pipeline.py" --n 50 --repeat 2 | tee "$work/baseline.txt"
python3 - "$work/sylva-pipeline.txt" "$work/baseline.txt" <<'PY'
import re, statistics, sys
sylva = dict(re.findall(r"^summary region=(\S+) warm_ms=([\d.]+)", open(sys.argv[1]).read(), re.M))
warm = [float(m) for m in re.findall(r"\(warm\d\)\s+n=\d+ total median ([\d.]+) ms", open(sys.argv[2]).read())]
base = statistics.median(warm)
print(f"\nbaseline (python, median of warm runs): {base:.1f} ms per 512² tile")
for region, ms in sylva.items():
    print(f"sylva {region}: {float(ms):.1f} ms per 513² tile + 32 halo -> {base / float(ms):.1f}x faster")
PY
