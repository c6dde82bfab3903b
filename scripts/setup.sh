#!/usr/bin/env bash
# Installs what Sylva needs on a fresh Debian machine: a C toolchain and
# certificates for cargo, GDAL's command-line tools and OWSLib (the tests read
# our GeoTIFFs and our WMS with them), Mesa's software Vulkan and OpenGL for
# the renderer, redis-server (the tests start one for the shared Redis tile
# cache), Xvfb (the viewer's tests open a window on it), and Rust through
# rustup when cargo is missing.
# Safe to run again: it installs only what is absent.
set -euo pipefail
sudo=""
[ "$(id -u)" = 0 ] || sudo=sudo
need=()
command -v cc >/dev/null || need+=(gcc libc6-dev)
command -v curl >/dev/null || need+=(curl ca-certificates)
command -v gdalinfo >/dev/null || need+=(gdal-bin)
/usr/bin/python3 -c 'import owslib' 2>/dev/null || need+=(python3-owslib)
# The renderer's tests run wgpu on Mesa's software Vulkan (lavapipe) when
# the machine has no GPU.
[ -e /usr/share/vulkan/icd.d/lvp_icd.x86_64.json ] || need+=(mesa-vulkan-drivers libvulkan1)
# ... and on its software OpenGL (llvmpipe through EGL), the second backend.
ls /usr/lib/*/libEGL.so.1 >/dev/null 2>&1 || need+=(libegl1)
ls /usr/lib/*/dri/swrast_dri.so >/dev/null 2>&1 || need+=(libgl1-mesa-dri)
command -v redis-server >/dev/null || need+=(redis-server)
# `sylva view`'s tests open its window on a virtual X display.
command -v Xvfb >/dev/null || need+=(xvfb)
if [ ${#need[@]} -gt 0 ]; then
  $sudo apt-get update -qq
  DEBIAN_FRONTEND=noninteractive $sudo apt-get install -y -qq --no-install-recommends "${need[@]}"
fi
if ! command -v cargo >/dev/null; then
  [ -x "$HOME/.cargo/bin/cargo" ] || curl -sSf https://sh.rustup.rs | sh -s -- -y --profile minimal
  echo "Rust installed in ~/.cargo; run: source ~/.cargo/env" >&2
fi
