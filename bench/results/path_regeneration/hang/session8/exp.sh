# Builds .gl/v<TAG> trees side by side after unpacking the debs, then runs the hang sequences.
set -u
export VK_DRIVER_FILES=/usr/local/nvidia/share/vulkan/icd.d/nvidia_icd.json
for f in .gl/*.deb; do dpkg -x "$f" /; done; ldconfig
rm -rf /tmp/pxdeps && mkdir -p /tmp/pxdeps; for f in .gl/extra/*.deb; do dpkg -x "$f" /tmp/pxdeps; done
t0=$(date +%s)
bash .gl/build_more.sh "$@" 2>&1 | tail -20
echo "built in $(( $(date +%s) - t0 )) s"
nvidia-smi --query-gpu=name,driver_version --format=csv,noheader
FULL="clocks:pt,nee,mis,guiding_pt_device,guiding_device light_behind_glass:pt,nee,mis,guiding_pt_device,guiding_device"
SHORT="clocks:guiding_device light_behind_glass:guiding_pt_device"
run() { local tag=$1 name=$2; shift 2; echo "== $name"; timeout -s KILL 75 env PARALLAX_DEVICE_TIMEOUT_S=10 PYTHONPATH=/tmp/pxsite-$tag:$PWD "$@" > $OUT/$name.log 2>&1; echo "rc $?"; grep -E "ERROR|Timeout|ms |rays after|robust|private" $OUT/$name.log | head -40; }
D="python3 .gl/regen_diag.py bench/npz"
GG="light_behind_glass:guiding_device light_behind_glass:guiding_pt_device"
run R U_full env PX_UNIQUE_ENTRY=1 $D $FULL
run R U_gg env PX_UNIQUE_ENTRY=1 $D $GG
run R N_full env PX_NO_SHARE=1 $D $FULL
run R U_full2 env PX_UNIQUE_ENTRY=1 $D $FULL
run R UN_gg env PX_UNIQUE_ENTRY=1 PX_NO_SHARE=1 $D $GG
echo "all done in $(( $(date +%s) - t0 )) s"
