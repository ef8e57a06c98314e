#!/usr/bin/env bash
# `make asan`: builds the core with AddressSanitizer + UndefinedBehaviorSanitizer (LeakSanitizer
# included) into build-asan/, and runs the unit and render tiers against it. Python, numpy and
# Mesa are not instrumented: libasan is preloaded, and scripts/asan_check.py reads the
# sanitizers' logs, failing on any error and on any leak with a frame in the core.
# Usage: scripts/asan.sh [PYTHON] [--ci] [pytest args...]
#   default: .venv/bin/python, the unit and render tiers (`make asan`);
#   --ci: the unit tier (but the bench tools', the Mitsuba peer's and the numpy-only modules'
#         tests) and CI_RENDER below, a render subset that runs every technique (.ci/run).
set -euo pipefail
cd "$(dirname "$0")/.."
PY=${1:-.venv/bin/python}
shift || true
# The render tests of --ci: each method (pt, nee, mis; on one session, 11 s where the glass
# furnace's 16 NEE batches took 31-42 s), the irradiance cache, ADRRS (which needs the cache),
# guiding with the CPU fit (lavapipe's "auto": the same-seed test) and the device fit, a partial
# update of each scene part and concurrent sessions (the host code the sanitizers watch). Small
# images, seconds each without ASan. Left out as repeats of host code the list already runs:
# ADRRS' same-seed test (its toggle test renders ADRRS, the cache and a scene edit, and now pays
# the cold compile), the specular furnaces, 14 of the 20 partial-update edits, the
# refined-regions test's CPU-fit case (the same-seed test's fit).
PARTIAL=tests/render/test_partial_update.py::test_partial_update_matches_a_full_one
CI_RENDER=(
  tests/render/test_integrator.py::test_pt_nee_mis_agree_on_cornell_box
  tests/render/test_irradiance_cache.py::test_same_seed_same_cache_and_image
  tests/render/test_irradiance_cache.py::test_scene_edit_drops_stale_irradiance
  tests/render/test_adrrs.py::test_toggle_resets_and_scene_edit_remakes_the_estimate
  tests/render/test_guiding.py::test_same_seed_same_image_fit_included
  "tests/render/test_guiding.py::test_refined_regions_reach_the_shaders[device]"
  "$PARTIAL[camera-orbit]" "$PARTIAL[instances-move-emitter]" "$PARTIAL[materials-texture]"
  "$PARTIAL[lights-world-map]" "$PARTIAL[geometry-scale]" "$PARTIAL[several-parts]"
  tests/render/test_sessions.py::test_concurrent_sessions_match_sequential
)
TESTS=("$@")
if [ "${1:-}" = --ci ]; then
  # Two workers, as make test has: CI's whole run (make test, then this) took 29.6 min on
  # serial sanitizer tests on a slower 2-core machine (12.5 of them here).
  # The unit tier but the bench tools' and the Mitsuba peer's tests: they time or compare
  # renders (Cycles and Mitsuba under the preloaded sanitizers, 2-3x their time) whose
  # Parallax side is plain MIS, which the render subset runs. Nor the sky model's and the node
  # fields' (parallax_core.sky, .node_fields): numpy only, no native code to watch, and 75 of
  # the unit tier's 520 s under the preload. make asan runs them all.
  TESTS=(-n 2 --dist loadfile tests/unit --ignore=tests/unit/test_bench_converge.py
         --ignore=tests/unit/test_bench_smoke.py --ignore=tests/unit/test_mitsuba_peer.py
         --ignore=tests/unit/test_sky.py --ignore=tests/unit/test_node_fields.py
         "${CI_RENDER[@]}" "${@:2}")
fi
[ ${#TESTS[@]} -gt 0 ] || TESTS=(tests/unit tests/render)
BUILD=build-asan
start=$(date +%s)
# -g1: line tables only, which is all the sanitizers' reports use (112 s -> 81 s to build here);
# -O1, as the sanitizers' documentation suggests: 113 s -> 85 s to build (2026-12-07), and the
# tests' time is lavapipe's and Python's, not the instrumented host code's.
cmake -S . -B $BUILD -DPython_EXECUTABLE="$(cd "$(dirname "$PY")" && pwd)/$(basename "$PY")" -DCMAKE_BUILD_TYPE=RelWithDebInfo \
      "-DCMAKE_CXX_FLAGS_RELWITHDEBINFO=-O1 -g1 -DNDEBUG" -DPARALLAX_SANITIZE=address,undefined >/dev/null
cmake --build $BUILD -j"$(nproc)"
# A site directory that shadows the installed packages: the package's .py files, the
# instrumented module, and the add-on.
SITE=$BUILD/site
rm -rf $SITE && mkdir -p $SITE/parallax_core
ln -s "$PWD"/native/python/parallax_core/*.py $SITE/parallax_core/
ln -s "$PWD"/$BUILD/_native*.so $SITE/parallax_core/
ln -s "$PWD"/addon $SITE/parallax_blender
LOGS=$BUILD/logs
rm -rf $LOGS && mkdir -p $LOGS
built=$(date +%s)
# detect_leaks: LeakSanitizer at each process's exit; exitcode=0 because Python always leaves
# objects behind (tests that run subprocesses check their exit status): the logs decide.
# Validation is off here (the normal suite runs under the layer).
status=0
# The preload: Python is not instrumented, so the ASan runtime must come first in the process
# (LD_PRELOAD of gcc's libasan.so, the one the module was linked against; ASan refuses to start
# otherwise: "ASan runtime does not come first in initial library list"). libstdc++ preloaded
# too: ASan's __cxa_throw interceptor needs it at start-up (python3 does not link it), or the
# core's first C++ exception stops the process. Subprocesses (the CLI tests) inherit both.
LD_PRELOAD="$(gcc -print-file-name=libasan.so) $(gcc -print-file-name=libstdc++.so.6)" \
ASAN_OPTIONS="detect_leaks=1:exitcode=0:log_path=$PWD/$LOGS/asan:strict_string_checks=1:check_initialization_order=1" \
UBSAN_OPTIONS="print_stacktrace=1:log_path=$PWD/$LOGS/ubsan" \
PARALLAX_VALIDATION=0 PYTHONPATH="$PWD/$SITE" \
  "$PY" -m pytest -q -p no:cacheprovider "${TESTS[@]}" || status=$?
"$PY" scripts/asan_check.py $LOGS || status=1
echo "make asan: build $((built - start)) s, tests $(( $(date +%s) - built )) s, status $status"
exit $status
