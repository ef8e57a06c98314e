# After one scripts/device_build.sh (debs unpacked, /tmp/pxdeps ready): builds .gl/v<TAG> trees in parallel.
set -e
export PATH=/tmp/pxdeps/usr/bin:$PATH
loader=$(ldconfig -p | awk '/libvulkan.so.1 /{print $NF; exit}')
for tag in "$@"; do (
  root=$PWD/.gl/v$tag
  cmake -S $root -B /tmp/pxbuild-$tag -DCMAKE_BUILD_TYPE=Release -DPython_EXECUTABLE=$(command -v python3) \
    -DVulkan_INCLUDE_DIR=/tmp/pxdeps/usr/include -DVulkan_LIBRARY=$loader >/tmp/pxbuild-$tag.log 2>&1 &&
  cmake --build /tmp/pxbuild-$tag -j 6 >>/tmp/pxbuild-$tag.log 2>&1 || { echo "build $tag failed"; tail -20 /tmp/pxbuild-$tag.log; }
  rm -rf /tmp/pxsite-$tag && mkdir -p /tmp/pxsite-$tag && cp -r $root/native/python/parallax_core /tmp/pxsite-$tag/ &&
  cp /tmp/pxbuild-$tag/_native*.so /tmp/pxsite-$tag/parallax_core/ ) & done
wait
