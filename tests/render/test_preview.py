"""The preview program (RenderParams.preview, shaders/preview.rgen): the viewport's first
frame while the path tracer compiles (issue 9). Its camera rays are the path tracer's, so its
depth, normal and albedo passes equal the path tracer's at one sample; its colour is the
base colour lit by a headlight plus emission. Session.compile() builds a pipeline without
rendering, and pipeline_ready says whether the next render has to compile."""
import json
import subprocess
import sys
import textwrap

import numpy as np
import pytest

import parallax_core as pc
from parallax_core import scenes


def one_frame(**params):
    s = pc.Session(48, 48)
    s.set_params(samples_per_frame=1, seed=5, **{**pc.UNBIASED_LIGHT_PATHS, **params})
    s.update(scenes.cornell_box(48, 48))
    s.render(1)
    return s.read_all()


def test_preview_sees_what_the_path_tracer_sees():
    quick, traced = one_frame(preview=True), one_frame(method="mis")
    for name in ("depth", "normal", "albedo"):
        np.testing.assert_allclose(quick[name], traced[name], rtol=1e-5, atol=1e-6, err_msg=name)
    combined, albedo = quick["combined"][..., :3], quick["albedo"]
    lit = albedo.max(-1) > 0.01
    light = np.isclose(combined, (17.0, 12.0, 4.0)).all(-1)  # the light's emission (black base)
    assert light.any() and (light == (~lit & (combined.max(-1) > 0))).all()
    ratio = combined[lit] / albedo[lit]
    assert (ratio >= 0.2 - 1e-4).all() and (ratio <= 1.0 + 1e-4).all()  # 0.2 + 0.8 cos
    assert np.allclose(ratio, ratio[:, :1], rtol=1e-4)  # grey light: the colour is the albedo's
    assert (quick["ray_depth"] == 1).all()


def test_preview_has_no_irradiance_cache():
    s = pc.Session(8, 8)
    with pytest.raises(ValueError, match="preview"):
        s.set_params(preview=True, ic=True)


def test_compile_without_rendering():
    # A process of its own: pipelines are shared process-wide, so in this one they may exist.
    code = textwrap.dedent("""
        import json, parallax_core as pc
        from parallax_core import scenes
        s = pc.Session(16, 16)
        s.set_params(method="nee", preview=True)
        s.update(scenes.cornell_box(16, 16))
        out = {"before": s.pipeline_ready}
        s.compile()
        out["after"], out["samples"] = s.pipeline_ready, s.samples
        s.set_params(preview=False)
        out["path_tracer"] = s.pipeline_ready
        s.render(1)
        out["rendered"] = s.pipeline_ready
        print(json.dumps(out))
    """)
    run = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=600)
    assert run.returncode == 0, run.stderr
    got = json.loads(run.stdout.strip().splitlines()[-1])
    assert got == {"before": False, "after": True, "samples": 0, "path_tracer": False, "rendered": True}
