# The working tree (regeneration + per-pipeline entry names) on the H200: the hang sequences,
# then equal-time guiding on light behind glass.
set -u
export VK_DRIVER_FILES=/usr/local/nvidia/share/vulkan/icd.d/nvidia_icd.json
t0=$(date +%s)
P=$(PX_DEBS=$PWD/.gl bash scripts/device_build.sh) || { echo build failed; exit 1; }
echo "built in $(( $(date +%s) - t0 )) s"
nvidia-smi --query-gpu=name,driver_version --format=csv,noheader
FULL="clocks:pt,nee,mis,guiding_pt_device,guiding_device light_behind_glass:pt,nee,mis,guiding_pt_device,guiding_device"
GG="light_behind_glass:guiding_device light_behind_glass:guiding_pt_device"
SHORT="clocks:guiding_device light_behind_glass:guiding_pt_device"
D="python3 .gl/regen_diag.py bench/npz"
run() { local name=$1; shift; echo "== $name"; timeout -s KILL 75 env PARALLAX_DEVICE_TIMEOUT_S=10 PYTHONPATH=$P:$PWD "$@" > $OUT/$name.log 2>&1; echo "rc $?"; grep -E "ERROR|Timeout|ms " $OUT/$name.log | head -40; }
run full1 $D $FULL
run gg $D $GG
run short $D $SHORT
run full2 $D $FULL
echo "hang runs done at $(( $(date +%s) - t0 )) s"
mkdir -p $OUT/converge
timeout -s KILL 300 env PYTHONPATH=$P:$PWD python3 -m bench.converge --npz bench/npz --scenes light_behind_glass \
  --methods pt,guiding_pt,guiding_pt_device,guiding,guiding_device --seconds 10 --peers "" --device gpu --warm \
  --reference-seconds 60 --out $OUT/converge > $OUT/converge.log 2>&1
echo "converge rc $? at $(( $(date +%s) - t0 )) s"; tail -15 $OUT/converge.log
cp -r bench/references $OUT/ 2>/dev/null
