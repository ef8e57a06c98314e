"""Several sessions at once (Blender has a viewport and an F12 render): they share the
device, may run on different threads, and give the same images as one at a time."""
import threading

import numpy as np

import parallax_core as pc
from parallax_core import scenes

from helpers import same_render


def render_once(scene, seed, frames=3):
    s = pc.Session(scene.width, scene.height)
    s.set_params(method="mis", samples_per_frame=2, seed=seed)
    s.update(scene)
    s.render(frames)
    return s.read("combined")


def test_concurrent_sessions_match_sequential():
    scene = scenes.cornell_box(24, 24)
    expected = [render_once(scene, seed) for seed in range(3)]
    results = [None] * 3

    def work(i):
        results[i] = render_once(scene, i)

    threads = [threading.Thread(target=work, args=(i,)) for i in range(3)]
    for t in threads:
        t.start()
    for t in threads:
        t.join(timeout=120)
    device_type = pc.Session(4, 4).device_type
    for got, want in zip(results, expected):
        assert got is not None and same_render(got, want, device_type)


def test_many_sessions_share_one_device():
    # One VkDevice per session would exhaust drivers; sessions share a process-wide one.
    sessions = [pc.Session(4, 4) for _ in range(32)]
    scene = scenes.cornell_box(4, 4)
    for s in sessions[::8]:
        s.update(scene)
        s.render(1)
        assert np.isfinite(s.read("combined")).all()
