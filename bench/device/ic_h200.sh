#!/usr/bin/env bash
# One device call for issue 33 (the irradiance cache): builds this tree and a base side by side,
# then (1) PT/NEE/MIS frames against the base, every technique off, (2) the cache's frame cost
# (MIS, consistent and thesis modes) against the base at 1280 px, (3) equal time at 1280 px:
# MIS and both cache modes for SECONDS with their convergence curves, against MIS references
# of REF_SECONDS, on the scenes named (as many as the time allows).
#
# Here, beforehand (the device machine has no git history and no internet):
#   .venv/bin/python bench/regression.py BASE --export .wt/src && (cd .wt && tar czf h200/src.tgz src) && rm -rf .wt/src
#   .venv/bin/python -m bench.converge --export-only --npz .wt/h200/npz --width 320 --scenes S1,S2,...
#   .venv/bin/python -m bench.converge --export-only --npz .wt/h200/npz1280 --width 1280 --scenes S1,S2,...
#   the Vulkan loader .debs in .gl/ (bench/README.md)
# Then: run(command="bash bench/device/ic_h200.sh BASE [1280-PX SCENES] [STAGES]", carry=[".gl", ".wt/h200"]),
# STAGES a subset of 123 (default all); SECONDS_RUN (10) and REF_SECONDS (100) from the environment.
# Waits name their PIDs: a bare `wait` also waits for process substitutions and can hang.
# Files back (at most 8): log.txt, frames.{txt,json}, ic_frames.{txt,json}, ic1280.txt, ic1280.tgz.
set -u
BASE=${1:?base commit (exported to .wt/h200/src.tgz)}
scenes1280=${2:-sun_room,thesis_irradiance_cache}
stages=${3:-123}
BUDGET=${BUDGET:-570}
. bench/device/setup.sh
if [[ $stages == *1* ]]; then
    timeout 150 python3 bench/regression.py "$BASE=.wt/src/$BASE" new=. --benches frame_cost --npz .wt/h200/npz \
        --scenes cornell_box,veach_mis,sun_room,atrium,light_behind_glass --methods pt,nee,mis --rounds 2 --seconds 0.5 \
        --device gpu --debs .gl --json "$OUT/frames.json" >"$OUT/frames.txt" 2>>"$OUT/log.txt"
    log "frames rc=$?"
fi
if [[ $stages == *2* ]]; then
    timeout 150 python3 bench/regression.py "$BASE=.wt/src/$BASE" new=. --benches frame_cost --npz .wt/h200/npz1280 \
        --scenes sun_room,thesis_irradiance_cache,veach_mis --methods mis,ic,ic_thesis --spp 8 --rounds 1 --seconds 1 \
        --device gpu --debs .gl --json "$OUT/ic_frames.json" >"$OUT/ic_frames.txt" 2>>"$OUT/log.txt"
    log "ic frames rc=$?"
fi
if [[ $stages == *3* ]]; then
    PYTHONPATH=/tmp/pxsite-new timeout $(( $(left) - 15 )) python3 -m bench.converge --npz .wt/h200/npz1280 --width 1280 \
        --scenes "$scenes1280" --methods mis,ic,ic_thesis --peers "" --seconds "${SECONDS_RUN:-10}" \
        --reference-seconds "${REF_SECONDS:-100}" --warm --device gpu --out /tmp/ic1280 >/tmp/ic1280_full.txt 2>&1
    log "ic1280 rc=$?"
    tr '\r' '\n' </tmp/ic1280_full.txt | grep -v -E 'spp *$|preparing *$' >"$OUT/ic1280.txt"
    rm -rf /tmp/ic1280/raw && tar czf "$OUT/ic1280.tgz" -C /tmp ic1280
fi
log "done"
