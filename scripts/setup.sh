#!/usr/bin/env bash
# Installs what Sylva needs on a fresh Debian machine: a C toolchain and
# certificates for cargo, GDAL's command-line tools and OWSLib (the tests read
# our GeoTIFFs and our WMS with them), Mesa's software Vulkan and OpenGL for
# the renderer, redis-server (the tests start one for the shared Redis tile
# cache), Xvfb and the X11 libraries winit opens (the viewer's tests open a
# window), Node.js with CesiumJS's engine (the tests read our Cesium terrain
# with it, from tests/cesium), and Rust through rustup when cargo is missing.
# Safe to run again: it installs only what is absent.
set -euo pipefail
sudo=""
if [ "$(id -u)" != 0 ]; then
  command -v sudo >/dev/null || { echo "setup.sh: run as root, or install sudo" >&2; exit 1; }
  sudo=sudo
fi
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
command -v npm >/dev/null || need+=(nodejs npm)
# `sylva view`'s tests open its window on a virtual X display, through the
# X11 libraries winit loads at run time.
command -v Xvfb >/dev/null || need+=(xvfb)
for lib in libxkbcommon-x11.so.0:libxkbcommon-x11-0 libXcursor.so.1:libxcursor1 libXi.so.6:libxi6 \
  libX11-xcb.so.1:libx11-xcb1; do
  ls /usr/lib/*/"${lib%%:*}" >/dev/null 2>&1 || need+=("${lib##*:}")
done
if [ ${#need[@]} -gt 0 ]; then
  $sudo apt-get update -qq
  $sudo env DEBIAN_FRONTEND=noninteractive apt-get install -y -qq --no-install-recommends "${need[@]}"
fi
# CesiumJS's engine as tests/cesium's lock pins it, for the terrain tests
# (again whenever the lock changes).
cesium="$(dirname "$0")/../tests/cesium"
if ! cmp -s "$cesium/package-lock.json" "$cesium/node_modules/.installed-lock.json"; then
  npm ci --prefix "$cesium" --no-audit --no-fund --loglevel=error
  cp "$cesium/package-lock.json" "$cesium/node_modules/.installed-lock.json"
fi
if ! command -v cargo >/dev/null; then
  [ -x "$HOME/.cargo/bin/cargo" ] || curl -sSf https://sh.rustup.rs | sh -s -- -y --profile minimal
  echo "Rust installed in ~/.cargo; run: source ~/.cargo/env" >&2
fi
