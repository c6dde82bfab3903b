#!/usr/bin/env bash
# The README's main command: installs what is missing (scripts/setup.sh), then
# builds and runs `sylva serve` in release mode. Without arguments it serves
# the embedded demo region on 127.0.0.1:8080; arguments go to `sylva serve`
# (e.g. --config config/examples/rmnp.toml --bind 0.0.0.0:8080).
set -euo pipefail
cd "$(dirname "$0")/.."
bash scripts/setup.sh
[ -x "$HOME/.cargo/bin/cargo" ] && export PATH="$HOME/.cargo/bin:$PATH"
exec cargo run --release --locked -- serve "$@"
