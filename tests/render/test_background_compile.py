"""Switching a technique on never blocks (issue 32, item 5): with Session.background_compile,
frames render with the techniques off while their pipelines compile on a worker thread.

Each check runs in a child process: pipelines are shared process-wide, so only a new process
is sure to meet a technique's pipelines uncompiled (its first frame then always falls back:
the compile starts in that very call). The first two set helpers.render's light paths: the
pipelines the render tier compiles anyway (CI time)."""
import json
import os
import subprocess
import sys
import textwrap

CHILD = textwrap.dedent("""
    import json, sys
    import numpy as np
    import parallax_core as pc
    from parallax_core import scenes

    background = sys.argv[1] == "1"
    scene = scenes.cornell_box(24, 24)
    s = pc.Session(24, 24, "cpu")
    s.update(scene)
    s.set_params(method="mis", rrs="adrrs", samples_per_frame=2, **pc.UNBIASED_LIGHT_PATHS)
    s.background_compile = background
    s.render(1)
    first = s.stats()
    plain = pc.Session(24, 24, "cpu")
    plain.update(scene)
    plain.set_params(method="mis", samples_per_frame=2, **pc.UNBIASED_LIGHT_PATHS)
    plain.render(1)
    same_as_plain = bool(np.array_equal(s.read("combined"), plain.read("combined")))
    pc.wait_for_background_compiles()
    s.render(1)
    after = s.stats()
    keys = ("samples", "fallback_samples", "adrrs_estimate_frames")
    print(json.dumps({"first": {k: first[k] for k in keys}, "after": {k: after[k] for k in keys},
                      "same_as_plain": same_as_plain, "ready": s.pipeline_ready,
                      "in_flight": pc.background_compiles()}))
""")

WARM_CHILD = textwrap.dedent("""
    import json
    import parallax_core as pc
    from parallax_core import scenes

    def session():  # as the add-on's warm-up and its F12: the film of a default view layer
        s = pc.Session(16, 16, "cpu")
        s.passes = ["combined"]
        s.update(scenes.cornell_box(16, 16))
        s.set_params(method="nee", guiding=True, samples_per_frame=1)
        return s

    s = session()
    s.warm()
    started = pc.background_compiles()
    ready_at_once = s.pipeline_ready
    pc.wait_for_background_compiles()
    f12 = session()
    f12.background_compile = True
    f12.render(1)
    print(json.dumps({"started": started, "ready_at_once": ready_at_once, "ready": s.pipeline_ready,
                      "f12_fallback_samples": f12.stats()["fallback_samples"]}))
""")


def run_child(code, *args):
    out = subprocess.run([sys.executable, "-c", code, *args], capture_output=True, text=True, timeout=900,
                         env=dict(os.environ))
    assert out.returncode == 0, out.stderr[-3000:]
    return json.loads(out.stdout.strip().splitlines()[-1])


def test_a_compiling_technique_renders_its_fallback_then_starts_the_film_over():
    r = run_child(CHILD, "1")
    # The first frame came from the pipeline without ADRRS: the very image plain MIS renders.
    assert r["first"] == {"samples": 2, "fallback_samples": 2, "adrrs_estimate_frames": 0}
    assert r["same_as_plain"]
    # Once compiled, ADRRS' estimate frames run and the film holds its frame alone.
    assert r["after"]["adrrs_estimate_frames"] > 0
    assert r["after"]["samples"] == 2 and r["after"]["fallback_samples"] == 2
    assert r["ready"] and r["in_flight"] == 0


def test_without_background_compiles_a_render_waits_for_its_technique():
    r = run_child(CHILD, "0")
    assert r["first"]["fallback_samples"] == 0 and r["first"]["adrrs_estimate_frames"] > 0
    assert not r["same_as_plain"]
    assert r["after"]["samples"] == 4


def test_warm_compiles_in_the_background_and_returns_at_once():
    r = run_child(WARM_CHILD)
    assert r["started"] == 1 and not r["ready_at_once"]
    assert r["ready"]
    assert r["f12_fallback_samples"] == 0  # the F12 after it found its pipeline warm
