#!/usr/bin/env bash
# One device call for issue 32's soup (and issue 34's EARS pipeline) read through the driver's
# own statistics: builds this tree, a base and any variant trees side by side, then
# (1) bench/pipeline_stats.py for this tree (the soup's PT/NEE/MIS pipelines, NEE with the
#     known-slow 1-vec4 payload reserve as the check that the statistics see what the clock sees,
#     and MIS/ADRRS/EARS/cache pipelines of two 320-px scenes) and for each variant (the soup);
# (2) the soup at 1k and 1M (NEE) for base, this tree and the variants, interleaved;
# (3) PT/NEE/MIS frames of this tree against the variants on FRAME_SCENES, if time is left.
# Results: bench/results/light_tree_fold/README.md names the variant this was written for.
#
# Here, beforehand (the device machine has no git history and no internet):
#   .venv/bin/python bench/regression.py BASE --export .wt/src     # and each variant tree as .wt/src/NAME
#   (cd .wt && tar czf h200/src.tgz src) && rm -rf .wt/src
#   .venv/bin/python -m bench.converge --export-only --npz .wt/h200/npz --width 320 --suite blender
#   .venv/bin/python -m bench.converge --export-only --npz .wt/h200/npz --width 320 --suite thesis
#   the Vulkan loader .debs in .gl/ (bench/README.md)
# Then: run(command="bash bench/device/stats_h200.sh BASE [VARIANT ...]", carry=[".gl", ".wt"]).
# At most 8 files come back from $OUT: log.txt, stats.md, stats.jsonl, soup.{md,json}, frames.{md,json}.
set -u
BASE=${1:?base commit (exported to .wt/h200/src.tgz)}
shift
VARIANTS=("$@")
FRAME_SCENES=${FRAME_SCENES:-atrium,sun_room,thesis_irradiance_cache}
BUDGET=${BUDGET:-570}
. bench/device/setup.sh
pids=()
for v in "${VARIANTS[@]}"; do
    PX_SRC=$PWD/.wt/src/$v PX_TAG=$v PX_JOBS=8 PX_PYTHON=python3 bash scripts/device_build.sh >"/tmp/build_$v.txt" 2>&1 &
    pids+=($!)
done
[ ${#pids[@]} -gt 0 ] && wait "${pids[@]}"
log "variants built: ${VARIANTS[*]:-none}"
export PARALLAX_VALIDATION=0
stats() {  # NAME PYTHONPATH [ENV=VALUE ...] -- ARGS...
    local name=$1 site=$2
    shift 2
    echo "## $name"
    echo "{\"section\": \"$name\"}" >>"$OUT/stats.jsonl"  # the rows after it are this build's
    env PYTHONPATH="$site" PARALLAX_PIPELINE_STATS="$OUT/stats.jsonl" "$@" 2>&1 | tail -n +2
}
{
    stats new /tmp/pxsite-new timeout 120 python3 -m bench.pipeline_stats --soup 1000 --methods pt,nee,mis
    stats "new, PARALLAX_PAYLOAD_RESERVE=1" /tmp/pxsite-new PARALLAX_PAYLOAD_RESERVE=1 \
        timeout 60 python3 -m bench.pipeline_stats --soup 1000 --methods nee
    stats "new, 320 px" /tmp/pxsite-new timeout 200 python3 -m bench.pipeline_stats --npz .wt/h200/npz \
        --scenes cornell_box,sun_room --methods mis,adrrs,ears,ic
    for v in "${VARIANTS[@]}"; do
        stats "$v" "/tmp/pxsite-$v" timeout 120 python3 -m bench.pipeline_stats --soup 1000 --methods pt,nee,mis
    done
} >"$OUT/stats.md"
log "statistics done"
columns=("$BASE=.wt/src/$BASE" new=.)
for v in "${VARIANTS[@]}"; do columns+=("$v=.wt/src/$v"); done
timeout $(( $(left) * 2 / 3 )) python3 bench/regression.py "${columns[@]}" --sizes 1k,1M --methods nee --rounds 2 \
    --seconds 1 --device gpu --debs .gl --json "$OUT/soup.json" >"$OUT/soup.md" 2>>"$OUT/log.txt"
log "soup rc=$?"
if [ ${#VARIANTS[@]} -gt 0 ] && [ "$(left)" -gt 60 ]; then
    timeout $(( $(left) - 10 )) python3 bench/regression.py "${columns[@]:1}" --benches frame_cost --npz .wt/h200/npz \
        --scenes "$FRAME_SCENES" --methods pt,nee,mis --spp 64 --seconds 0.4 --passes combined --rounds 2 --device gpu \
        --debs .gl --json "$OUT/frames.json" >"$OUT/frames.md" 2>>"$OUT/log.txt"
    log "frames rc=$?"
fi
