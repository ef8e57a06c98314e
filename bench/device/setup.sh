# Sourced by the device scripts (bench/device/*_h200.sh) with BASE set: unpacks the carried
# Vulkan loader, builds this tree (tag `new`) and BASE (exported to .wt/h200/src.tgz) side by
# side into /tmp/pxsite-new and /tmp/pxsite-BASE, and defines log (to $OUT/log.txt) and left
# (seconds of the call's BUDGET, default 570, still left).
T0=$(date +%s)
log() { echo "[t=$(( $(date +%s) - T0 ))s] $*" | tee -a "$OUT/log.txt"; }
left() { echo $(( ${BUDGET:-570} - $(date +%s) + T0 )); }
for f in .gl/*.deb; do dpkg -x "$f" /; done
ldconfig
mkdir -p .wt && tar xzf .wt/h200/src.tgz -C .wt
PX_SRC=$PWD PX_TAG=new PX_JOBS=8 PX_PYTHON=python3 bash scripts/device_build.sh >/tmp/build_new.txt 2>&1 &
build_new=$!
PX_SRC=$PWD/.wt/src/$BASE PX_TAG=$BASE PX_JOBS=8 PX_PYTHON=python3 bash scripts/device_build.sh >/tmp/build_base.txt 2>&1 &
build_base=$!
wait $build_new $build_base  # by PID: a bare `wait` also waits for process substitutions and can hang
log "built"
tail -n 3 /tmp/build_new.txt /tmp/build_base.txt >>"$OUT/log.txt"
