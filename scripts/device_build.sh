#!/usr/bin/env bash
# Builds parallax_core on a machine without internet or a Vulkan SDK (the NVIDIA device
# machines): the Vulkan loader, headers and glslang come as .deb files in .gl/ (see
# bench/README.md), nanobind and scikit-build-core from that machine's Python.
# Usage: bash scripts/device_build.sh  -> prints the PYTHONPATH to use.
set -euo pipefail
root=$(cd "$(dirname "$0")/.." && pwd)
for f in "$root"/.gl/*.deb; do dpkg -x "$f" /; done
ldconfig
rm -rf /tmp/pxdeps && mkdir -p /tmp/pxdeps
for f in "$root"/.gl/extra/*.deb; do dpkg -x "$f" /tmp/pxdeps; done
export PATH=/tmp/pxdeps/usr/bin:$PATH
loader=$(ldconfig -p | awk '/libvulkan.so.1 /{print $NF; exit}')
cmake -S "$root" -B /tmp/pxbuild -DCMAKE_BUILD_TYPE=Release -DPython_EXECUTABLE="$(command -v python3)" \
  -DVulkan_INCLUDE_DIR=/tmp/pxdeps/usr/include -DVulkan_LIBRARY="$loader" >/tmp/pxbuild.log 2>&1 \
  || { cat /tmp/pxbuild.log; exit 1; }
cmake --build /tmp/pxbuild -j "$(nproc)" >>/tmp/pxbuild.log 2>&1 || { tail -50 /tmp/pxbuild.log; exit 1; }
rm -rf /tmp/pxsite && mkdir -p /tmp/pxsite
cp -r "$root/native/python/parallax_core" /tmp/pxsite/
cp /tmp/pxbuild/_native*.so /tmp/pxsite/parallax_core/
echo /tmp/pxsite
