#!/usr/bin/env bash
# Builds parallax_core on a machine without internet or a Vulkan SDK (the NVIDIA device
# machines): the Vulkan loader, headers and glslang come as .deb files in .gl/ (see
# bench/README.md), nanobind and scikit-build-core from that machine's Python.
# Usage: bash scripts/device_build.sh  -> prints the PYTHONPATH to use.
# PX_TAG names the build (several trees can be built side by side), PX_DEBS the .deb folder.
set -euo pipefail
root=$(cd "$(dirname "$0")/.." && pwd)
tag=${PX_TAG:-main}
debs=${PX_DEBS:-$root/.gl}
for f in "$debs"/*.deb; do dpkg -x "$f" /; done
ldconfig
rm -rf /tmp/pxdeps && mkdir -p /tmp/pxdeps
for f in "$debs"/extra/*.deb; do dpkg -x "$f" /tmp/pxdeps; done
export PATH=/tmp/pxdeps/usr/bin:$PATH
loader=$(ldconfig -p | awk '/libvulkan.so.1 /{print $NF; exit}')
cmake -S "$root" -B /tmp/pxbuild-$tag -DCMAKE_BUILD_TYPE=Release -DPython_EXECUTABLE="$(command -v python3)" \
  -DVulkan_INCLUDE_DIR=/tmp/pxdeps/usr/include -DVulkan_LIBRARY="$loader" >/tmp/pxbuild-$tag.log 2>&1 \
  || { cat /tmp/pxbuild-$tag.log; exit 1; }
cmake --build /tmp/pxbuild-$tag -j "$(nproc)" >>/tmp/pxbuild-$tag.log 2>&1 || { tail -50 /tmp/pxbuild-$tag.log; exit 1; }
rm -rf /tmp/pxsite-$tag && mkdir -p /tmp/pxsite-$tag
cp -r "$root/native/python/parallax_core" /tmp/pxsite-$tag/
cp /tmp/pxbuild-$tag/_native*.so /tmp/pxsite-$tag/parallax_core/
echo /tmp/pxsite-$tag
