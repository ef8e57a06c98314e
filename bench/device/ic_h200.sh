#!/usr/bin/env bash
# One device call for issue 33 (the consistent irradiance cache): builds this tree and a base
# side by side, then (1) PT/NEE/MIS frames against the base, every technique off, (2) MIS
# references at 320 px for the lavapipe runs (bench/references, the GPU's many samples),
# (3) equal time at 1280 px: MIS, the cache's consistent and thesis modes, 30 s with their
# convergence curves, 120-s references, on the scenes named (as many as the time allows).
#
# Here, beforehand (the device machine has no git history and no internet):
#   .venv/bin/python bench/regression.py BASE --export .wt/src && (cd .wt && tar czf h200/src.tgz src) && rm -rf .wt/src
#   .venv/bin/python -m bench.converge --export-only --npz .wt/h200/npz --width 320 --scenes S1,S2,...
#   .venv/bin/python -m bench.converge --export-only --npz .wt/h200/npz1280 --width 1280 --scenes S1,S2,...
#   the Vulkan loader .debs in .gl/ (bench/README.md)
# Then: run(command="bash bench/device/ic_h200.sh BASE [1280-PX SCENES] [SKIP_FRAMES]", carry=[".gl", ".wt/h200"]).
# Waits name their PIDs: a bare `wait` also waits for process substitutions and can hang.
# Files back (at most 8): log.txt, frames.{txt,json}, frames_err.txt, refs320.tgz, ic1280.txt, ic1280.tgz.
set -u
BASE=${1:?base commit (exported to .wt/h200/src.tgz)}
base=$BASE
scenes1280=${2:-sun_room,thesis_irradiance_cache}
skip_frames=${3:-0}
BUDGET=${BUDGET:-570}
. bench/device/setup.sh
if [ "$skip_frames" = 0 ]; then
    timeout 150 python3 bench/regression.py "$base=.wt/src/$base" new=. --benches frame_cost --npz .wt/h200/npz \
        --scenes cornell_box,veach_mis,sun_room,atrium,light_behind_glass --methods pt,nee,mis --rounds 2 --seconds 0.5 \
        --device gpu --debs .gl --json "$OUT/frames.json" >"$OUT/frames.txt" 2>"$OUT/frames_err.txt"
    log "frames rc=$?"
    PYTHONPATH=/tmp/pxsite-new timeout 200 python3 -m bench.converge --npz .wt/h200/npz --width 320 \
        --scenes sun_room,thesis_irradiance_cache,atrium,veach_mis,cornell_box --methods mis --peers "" --seconds 1 \
        --reference-seconds 20 --device gpu --out /tmp/refs320 >/tmp/refs320.txt 2>&1
    log "references rc=$?"
    (cd bench/references && tar czf "$OUT/refs320.tgz" ./*_320x*)
fi
PYTHONPATH=/tmp/pxsite-new timeout $(( $(left) - 15 )) python3 -m bench.converge --npz .wt/h200/npz1280 --width 1280 \
    --scenes "$scenes1280" --methods mis,ic,ic_thesis --peers "" --seconds 30 --reference-seconds 120 --warm \
    --device gpu --out /tmp/ic1280 >/tmp/ic1280_full.txt 2>&1
log "ic1280 rc=$?"
tr '\r' '\n' </tmp/ic1280_full.txt | grep -v -E 'spp *$|preparing *$' >"$OUT/ic1280.txt"
rm -rf /tmp/ic1280/raw && tar czf "$OUT/ic1280.tgz" -C /tmp ic1280
