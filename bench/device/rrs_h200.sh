#!/usr/bin/env bash
# One device call for issue 34's H200 figures (bench/results/gpu_rrs): builds this tree and a
# base side by side, then (1) PT/NEE/MIS frames against the base, (2) MIS/ADRRS/EARS frame costs
# with and without splits, (3) equal time at 320 px if time is left. Logs and tables go to $OUT.
#
# Here, beforehand (the device machine has no git history and no internet):
#   .venv/bin/python bench/regression.py BASE --export .wt/src && (cd .wt && tar czf h200/src.tgz src) && rm -rf .wt/src
#   .venv/bin/python -m bench.converge --export-only --npz .wt/h200/npz --width 320 \
#       --scenes cornell_box,veach_mis,sun_room,atrium,cornell_dielectric,light_behind_glass,clocks
#   the Vulkan loader .debs in .gl/ (bench/README.md)
# Then: run(command="bash bench/device/rrs_h200.sh BASE", carry=[".gl", ".wt"]).
# Waits name their PIDs: a bare `wait` also waits for process substitutions and can hang.
# At most 8 files come back from $OUT: log.txt, frames.{txt,json}, frames_err.txt,
# rrs_cost_split{0,1}.txt, conv.txt and conv.tgz (the per-scene tables).
set -u
BASE=${1:?base commit (exported to .wt/h200/src.tgz)}
base=$BASE
BUDGET=${BUDGET:-560}
. bench/device/setup.sh
timeout $(( $(left) / 3 )) python3 bench/regression.py "$base=.wt/src/$base" new=. --benches frame_cost --npz .wt/h200/npz \
    --scenes cornell_box,veach_mis,sun_room,atrium,light_behind_glass --methods pt,nee,mis --rounds 2 --seconds 0.5 \
    --device gpu --debs .gl --json "$OUT/frames.json" >"$OUT/frames.txt" 2>"$OUT/frames_err.txt"
log "frames rc=$?"
for split in 0 1; do
    PYTHONPATH=/tmp/pxsite-new timeout 90 python3 -m bench.frame_cost --npz .wt/h200/npz --scenes cornell_box,veach_mis,sun_room \
        --methods mis,adrrs,ears --spp 64 --seconds 1.5 --device gpu --set adrrs_splitting=$split \
        >"$OUT/rrs_cost_split$split.txt" 2>&1
    log "rrs split=$split rc=$?"
done
if [ "$(left)" -gt 120 ]; then
    PYTHONPATH=/tmp/pxsite-new timeout $(( $(left) - 20 )) python3 -m bench.converge --npz .wt/h200/npz --width 320 \
        --scenes cornell_box,veach_mis,sun_room --methods mis,adrrs,ears --peers "" --seconds 5 --reference-seconds 30 \
        --warm --device gpu --out /tmp/conv >"$OUT/conv.txt" 2>&1
    log "converge rc=$?"
    rm -rf /tmp/conv/raw && tar czf "$OUT/conv.tgz" -C /tmp conv
fi
