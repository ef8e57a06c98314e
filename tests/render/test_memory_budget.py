"""Device-memory budget (issue 9): the core counts every buffer and acceleration structure it
holds against a budget; a scene (or film) past it raises parallax_core.DeviceMemoryError, a
MemoryError, before anything is allocated past it, and the session keeps rendering the scene
it had."""
import gc
import os
import subprocess
import sys

import numpy as np
import pytest

import parallax_core as pc
from parallax_core import scenes
from parallax_core.scene import Material, Texture

MIB = 1 << 20


@pytest.fixture
def budget():
    """Sets the budget to what is in use now plus some MiB; restores the default after."""
    def set_headroom(mib):
        pc.set_memory_budget(pc.memory()["allocated"] + mib * MIB)
    yield set_headroom
    pc.set_memory_budget(0)


def textured_box(texture_side, w=16, h=16):
    sc = scenes.cornell_box(w, h)
    pixels = np.full((texture_side, texture_side, 4), 200, np.uint8)
    sc.textures.append(Texture(pixels, "big"))
    sc.materials.append(Material("diffuse", (1.0, 1.0, 1.0), base_color_texture=0, name="textured"))
    sc.meshes[2].material = len(sc.materials) - 1  # the back wall
    return sc


def big_mesh(w=16, h=16):
    return scenes.triangle_soup_scene(400_000, w, h)


@pytest.mark.parametrize("make_big", [lambda: textured_box(2048), big_mesh], ids=["texture", "mesh"])
def test_scene_past_the_budget_raises_and_the_session_goes_on(budget, make_big):
    s = pc.Session(16, 16)
    s.set_params(samples_per_frame=2, seed=3)
    s.update(scenes.cornell_box(16, 16))
    s.render(1)
    before = s.read("combined")
    gc.collect()  # earlier tests' sessions, if garbage, go now, not during the update below
    held = pc.memory()["allocated"]
    big = make_big()  # 2048² texels (16 MiB) or 400k triangles (over 20 MiB with the BLAS)
    budget(8)
    with pytest.raises(pc.DeviceMemoryError, match="does not fit.*budget") as err:
        s.update(big)
    assert isinstance(err.value, MemoryError)
    assert pc.memory()["allocated"] == held  # nothing of the failed upload is left
    s.reset()  # the old scene renders on, the same image as before
    s.render(1)
    np.testing.assert_array_equal(s.read("combined"), before)
    s.update(textured_box(64))  # a smaller scene still fits
    s.render(1)
    assert np.isfinite(s.read("combined")).all()


def test_film_past_the_budget_raises(budget):
    budget(4)
    with pytest.raises(pc.DeviceMemoryError, match="budget"):
        pc.Session(2048, 2048)  # 7 passes of float4: 448 MiB
    pc.Session(16, 16)


def test_memory_counts_what_sessions_hold():
    start = pc.memory()["allocated"]
    s = pc.Session(64, 64)
    film = pc.memory()["allocated"] - start
    # The film, at least: the base tracer's film passes (not those of techniques that are off,
    # nor Sample Count, Combined's w, nor the engine's Noisy Image; Session.passes).
    slots = [p for p in pc.PASSES if p.core and not p.setting and p.name != "sample_count"]
    assert film >= 64 * 64 * len(slots) * 16
    s.update(textured_box(256, 64, 64))
    assert pc.memory()["allocated"] - start >= film + 256 * 256 * 4
    del s
    assert pc.memory()["allocated"] == start


def test_default_budget_and_environment():
    m = pc.memory()
    share = 0.5 if pc.Session(4, 4).device_type == "cpu" else 0.8
    assert m["budget"] == int(m["heap"] * share) and m["heap"] > 0
    code = "import parallax_core as pc; print(pc.memory()['budget'])"
    run = lambda value: subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120,
                                       env={**os.environ, "PARALLAX_MEMORY_BUDGET": value})
    assert run("96M").stdout.strip() == str(96 * MIB)
    assert run("1.5G").stdout.strip() == str(3 * 512 * MIB)
    bad = run("lots")
    assert bad.returncode != 0 and "PARALLAX_MEMORY_BUDGET" in bad.stderr and "ValueError" in bad.stderr
