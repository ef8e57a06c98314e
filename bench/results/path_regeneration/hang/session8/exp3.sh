# A real hang (regeneration, lbg gmis then gpt) with the hung-device fix: does the process exit?
set -u
export VK_DRIVER_FILES=/usr/local/nvidia/share/vulkan/icd.d/nvidia_icd.json
for f in .gl/*.deb; do dpkg -x "$f" /; done; ldconfig
rm -rf /tmp/pxdeps && mkdir -p /tmp/pxdeps; for f in .gl/extra/*.deb; do dpkg -x "$f" /tmp/pxdeps; done
t0=$(date +%s)
bash .gl/build_more.sh H 2>&1 | tail -20
echo "built in $(( $(date +%s) - t0 )) s"
GG="light_behind_glass:guiding_device light_behind_glass:guiding_pt_device"
for i in 1; do
  s=$(date +%s)
  timeout -s KILL 45 env PX_EXIT_NORMALLY=1 PARALLAX_DEVICE_TIMEOUT_S=10 PYTHONPATH=/tmp/pxsite-H:$PWD python3 .gl/regen_diag.py bench/npz $GG > $OUT/exit_$i.log 2>&1
  echo "run $i rc $? after $(( $(date +%s) - s )) s"; grep -E "ERROR|deleted|ms " $OUT/exit_$i.log
done
