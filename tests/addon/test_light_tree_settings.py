"""The Light Tree checkbox (Cycles' scene.cycles.use_light_tree, default on): saved in the
.blend, passed to the core, shown in the Lights panel, parsed by --set, and a change restarts
the viewport. What it does to a render: tests/render/test_light_sampling.py."""
import dataclasses

from addon.cli import apply_settings
from blender_helpers import save_and_reopen
from test_ic_settings import _FakeDepsgraph, _FakeWorker

import parallax_core


def test_light_tree_round_trips_to_the_core(fresh, bpy, tmp_path):
    assert fresh.parallax.render_params()["light_tree"] is True
    assert parallax_core.RenderParams().light_tree is True
    fresh.parallax.light_tree = False
    scene = save_and_reopen(bpy, tmp_path / "light_tree.blend")
    params = scene.parallax.render_params()
    assert params["light_tree"] is False
    session = parallax_core.Session(4, 4, "cpu")
    session.set_params(**params)
    assert session.params.light_tree is False
    assert dataclasses.asdict(session.params)["light_tree"] is False


def test_light_tree_in_the_lights_panel_and_set(fresh, bpy):
    assert "light_tree" in bpy.types.PARALLAX_PT_lights.properties
    apply_settings(fresh, ["light_tree=0"])
    assert fresh.parallax.light_tree is False
    apply_settings(fresh, ["light_tree=on"])
    assert fresh.parallax.light_tree is True
    from parallax_core.cli import parse_params

    assert parse_params(["light_tree=0"]) == dict(light_tree=False)


def test_light_tree_change_restarts_the_viewport(fresh):
    from addon.engine import viewport

    view = viewport.ViewportRender()
    view.worker = _FakeWorker()
    depsgraph = _FakeDepsgraph(fresh)
    view.update(None, None, depsgraph)
    view.update(None, None, depsgraph)
    assert len(view.worker.submitted) == 1
    fresh.parallax.light_tree = False
    view.update(None, None, depsgraph)
    assert len(view.worker.submitted) == 2 and view.worker.submitted[-1]["params"]["light_tree"] is False
