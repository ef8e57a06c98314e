#!/usr/bin/env bash
# Builds parallax_core outside pip, one build per tag: on a machine without internet or a Vulkan
# SDK (the NVIDIA device machines) the Vulkan loader, headers and glslang come as .deb files in
# .gl/ (see bench/README.md), nanobind and scikit-build-core from that machine's Python; where
# the .deb folder holds none (a development machine), the system's Vulkan and glslang are used.
# Usage: bash scripts/device_build.sh  -> prints the PYTHONPATH to use.
# PX_TAG names the build (several trees can be built side by side: /tmp/pxbuild-TAG,
# /tmp/pxsite-TAG), PX_SRC the source tree (default: this script's), PX_DEBS the .deb folder,
# PX_PYTHON the Python to build for (default python3), PX_JOBS the parallel jobs (default nproc).
set -euo pipefail
root=${PX_SRC:-$(cd "$(dirname "$0")/.." && pwd)}
tag=${PX_TAG:-main}
debs=${PX_DEBS:-$(cd "$(dirname "$0")/.." && pwd)/.gl}
python=${PX_PYTHON:-python3}
vulkan=()
if compgen -G "$debs/*.deb" >/dev/null; then
  # The loader goes into / once; headers and glslang into a folder per build, so that several
  # builds can run side by side.
  if ! ldconfig -p | grep -q "libvulkan.so.1 "; then
    for f in "$debs"/*.deb; do dpkg -x "$f" /; done
    ldconfig
  fi
  deps=/tmp/pxdeps-$tag
  rm -rf "$deps" && mkdir -p "$deps"
  for f in "$debs"/extra/*.deb; do dpkg -x "$f" "$deps"; done
  export PATH=$deps/usr/bin:$PATH
  loader=$(ldconfig -p | awk '/libvulkan.so.1 /{print $NF; exit}')
  vulkan=(-DVulkan_INCLUDE_DIR=$deps/usr/include -DVulkan_LIBRARY="$loader")
fi
cmake -S "$root" -B /tmp/pxbuild-$tag -DCMAKE_BUILD_TYPE=Release -DPython_EXECUTABLE="$(command -v "$python")" \
  "${vulkan[@]}" >/tmp/pxbuild-$tag.log 2>&1 || { cat /tmp/pxbuild-$tag.log >&2; exit 1; }
cmake --build /tmp/pxbuild-$tag -j "${PX_JOBS:-$(nproc)}" >>/tmp/pxbuild-$tag.log 2>&1 \
  || { tail -50 /tmp/pxbuild-$tag.log >&2; exit 1; }
rm -rf /tmp/pxsite-$tag && mkdir -p /tmp/pxsite-$tag
cp -r "$root/native/python/parallax_core" /tmp/pxsite-$tag/
cp /tmp/pxbuild-$tag/_native*.so /tmp/pxsite-$tag/parallax_core/
echo /tmp/pxsite-$tag
