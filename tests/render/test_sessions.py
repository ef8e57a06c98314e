"""Several sessions at once (Blender has a viewport and an F12 render): they share the
device, may run on different threads, and give the same images as one at a time."""
import json
import os
import re
import subprocess
import sys
import threading
from pathlib import Path

import numpy as np
import pytest

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


def test_frames_in_row_bands_equal_whole_frames():
    """render_rows traces a frame in bands (interruptible dispatches) with the same samples."""
    scene = scenes.cornell_box(32, 24)
    whole = pc.Session(32, 24)
    whole.set_params(samples_per_frame=2)
    whole.update(scene)
    whole.render(3)
    banded = pc.Session(32, 24)
    banded.set_params(samples_per_frame=2)
    banded.update(scene)
    completed = [banded.render_rows(5) for _ in range(15)]  # 24 rows: 5+5+5+5+4, three times
    assert completed == [False, False, False, False, True] * 3 and banded.next_row == 0
    assert banded.stats()["samples"] == 6
    np.testing.assert_array_equal(banded.read("combined"), whole.read("combined"))
    # A frame begun in bands and finished by render() is still the same frame; reset drops one.
    banded.reset()
    assert banded.render_rows(10) is False and banded.next_row == 10
    banded.reset()
    assert banded.next_row == 0 and banded.stats()["samples"] == 0
    banded.render_rows(7)
    banded.render(2)
    whole.reset()
    whole.render(2)
    np.testing.assert_array_equal(banded.read("combined"), whole.read("combined"))


HUNG_DEVICE = """
import gc, os, parallax_core as pc
from parallax_core import scenes
s = pc.Session(48, 48)
s.set_params(method="mis", samples_per_frame=64)
s.update(scenes.cornell_box(48, 48))
os.environ["PARALLAX_DEVICE_TIMEOUT_S"] = "1e-6"  # read at every submission
errors = []
for frame in range(5):
    try:
        s.render(1)
    except RuntimeError as e:
        errors.append(str(e))
# The session's objects may still be in use by the abandoned submission: deleting the session
# must leave them alone (destroying them is what the validation layer would report here).
pc.validation_messages(clear=True)
del s
gc.collect()
in_use = [m for m in pc.validation_messages(clear=True) if "in use" in m]
print(len(in_use), len(errors), errors[0] if errors else "", errors[-1] == errors[0] if errors else "", flush=True)
os._exit(0)  # the device may still run the abandoned submission
"""


def test_a_device_past_its_timeout_raises_instead_of_hanging():
    # A hung device (the NVIDIA driver once hung in a frame: bench/results/path_regeneration)
    # must end in an error, not a wait for ever, and the session can still be deleted. A timeout
    # of a microsecond, far below any frame, stands in for the hang; a child process, since the
    # device stays marked hung.
    run = subprocess.run([sys.executable, "-c", HUNG_DEVICE], capture_output=True, text=True, timeout=300)
    assert run.returncode == 0, run.stderr
    in_use, count, message = run.stdout.split(" ", 2)
    # The first submission past the limit raises, and so does every later one, with the same reason.
    assert int(in_use) == 0 and int(count) == 5 and "taken for hung" in message and "PARALLAX_DEVICE_TIMEOUT_S" in message
    assert message.strip().endswith("True")


VECTOR_WIDTH = """
import ctypes, hashlib, parallax_core as pc
from parallax_core import scenes
getenv = ctypes.CDLL(None).getenv  # the C environment (os.environ is a copy from the start)
getenv.restype = ctypes.c_char_p
s = pc.Session(32, 32)
s.set_params(method="mis", samples_per_frame=4, seed=3)
s.update(scenes.cornell_box(32, 32))
s.render(2)
print(s.device_type, getenv(b"LP_NATIVE_VECTOR_WIDTH").decode(), hashlib.sha256(s.read("combined").tobytes()).hexdigest())
"""


def run_with_mesa_setting(script, name, value, cache):
    """stdout's words of `script` in a child process whose environment sets Mesa's `name` to
    `value` (None: unset, the core's choice), with a shader cache of its own at `cache`."""
    env = {k: v for k, v in os.environ.items() if k != name}
    env["MESA_SHADER_CACHE_DIR"] = str(cache)
    if value:
        env[name] = value
    run = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True, timeout=600, env=env)
    assert run.returncode == 0, run.stderr
    return run.stdout.split()


def test_lavapipe_runs_four_lanes_with_the_same_images(tmp_path):
    # The core sets LP_NATIVE_VECTOR_WIDTH=128 (fewer lanes idle per SIMD group: 5-9% faster
    # renders) unless the user chose a width; the images are bit for bit those of 256 bits.
    device, width, ours = run_with_mesa_setting(VECTOR_WIDTH, "LP_NATIVE_VECTOR_WIDTH", None, tmp_path / "default")
    if device != "cpu":
        pytest.skip("a GPU: no lavapipe to tune")
    _, chosen, wide = run_with_mesa_setting(VECTOR_WIDTH, "LP_NATIVE_VECTOR_WIDTH", "256", tmp_path / "wide")
    assert width == "128" and chosen == "256"
    assert ours == wide


CACHE_PARTS = """
import ctypes, parallax_core as pc
getenv = ctypes.CDLL(None).getenv
getenv.restype = ctypes.c_char_p
s = pc.Session(8, 8)
print(s.device_type, getenv(b"MESA_DISK_CACHE_DATABASE_NUM_PARTS").decode())
"""


def test_mesa_keeps_its_shader_cache_in_one_part(tmp_path):
    # Mesa's cache database caps each of its 50 parts at 1/50 of the cache and fills one part
    # at a time: about a hundred pipelines, then evictions. The core asks for one part (the
    # whole cache) unless the user chose a number; Mesa lays the cache out so.
    def child(parts, cache):
        words = run_with_mesa_setting(CACHE_PARTS, "MESA_DISK_CACHE_DATABASE_NUM_PARTS", parts, tmp_path / cache)
        return words, sorted(p.name for p in (tmp_path / cache / "mesa_shader_cache_db").glob("part*"))
    (device, ours), ours_layout = child(None, "ours")
    if device != "cpu":
        pytest.skip("a GPU: no Mesa cache")
    (_, chosen), chosen_layout = child("3", "chosen")
    assert (ours, ours_layout) == ("1", ["part0"])
    assert (chosen, chosen_layout) == ("3", ["part0", "part1", "part2"])


def test_mesa_cache_of_our_own_unless_the_user_chose_one(tmp_path):
    # Blender's OpenGL, where it is Mesa's, opens the default cache with 50 parts and trims the
    # part it writes to down to 21 MB: the core keeps its pipelines in XDG_CACHE_HOME/parallax.
    env = {k: v for k, v in os.environ.items() if k not in ("MESA_SHADER_CACHE_DIR", "MESA_DISK_CACHE_DATABASE_NUM_PARTS")}
    env["XDG_CACHE_HOME"] = str(tmp_path / "xdg")
    script = CACHE_PARTS + 'print(getenv(b"MESA_SHADER_CACHE_DIR").decode())\n'
    run = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True, timeout=600, env=env)
    assert run.returncode == 0, run.stderr
    device, parts, cache = run.stdout.split()
    if device != "cpu":
        pytest.skip("a GPU: no Mesa cache")
    assert (parts, cache) == ("1", str(tmp_path / "xdg" / "parallax"))
    assert sorted(p.name for p in (tmp_path / "xdg" / "parallax" / "mesa_shader_cache_db").glob("part*")) == ["part0"]
    env["MESA_SHADER_CACHE_DIR"] = str(tmp_path / "chosen")
    run = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True, timeout=600, env=env)
    assert run.returncode == 0, run.stderr
    assert run.stdout.split()[2] == str(tmp_path / "chosen")


def test_compile_log_and_pipeline_statistics_name_each_pipeline_created(tmp_path):
    # PARALLAX_COMPILE_LOG: "pipeline PID PPID MS STAGES" and the specialisation constants.
    # PARALLAX_PIPELINE_STATS: a JSON line per pipeline (bench/pipeline_stats.py reads it).
    log, stats = tmp_path / "compile.log", tmp_path / "stats.jsonl"
    script = """
import parallax_core as pc
from parallax_core import scenes
s = pc.Session(8, 8)
s.set_params(method="nee", samples_per_frame=1, seed=1)
s.update(scenes.cornell_box(8, 8))
s.render(1)
"""
    run = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True, timeout=600,
                         env={**os.environ, "PARALLAX_COMPILE_LOG": str(log), "PARALLAX_PIPELINE_STATS": str(stats)})
    assert run.returncode == 0, run.stderr
    lines = [line.split() for line in log.read_text().splitlines() if line.startswith("pipeline ")]
    assert lines, log.read_text()
    word, pid, ppid, ms, stages, *constants = lines[0]
    assert int(ppid) == os.getpid() and int(ms) >= 0 and int(stages) >= 3
    rows = re.findall(r"^\s*X\(\d+,", Path(__file__).parents[2].joinpath("shaders", "shared", "specialization.h").read_text(), re.M)
    assert len(constants) == len(rows) and all(c.isdigit() for c in constants)
    # The same pipelines, in the same order, with their constants by name and a stack size per
    # shader group (raygen, misses, hits); lavapipe reports no executables.
    entries = [json.loads(line) for line in stats.read_text().splitlines()]
    assert [[e["constants"][name] for name in e["constants"]] for e in entries] == [[int(c) for c in line[5:]] for line in lines]
    assert entries[0]["program"] == 0 and "method" in entries[0]["constants"]  # PROGRAM_CAMERA
    stack = entries[0]["driver"]["stack"]
    assert "general" in stack[0] and any("closest_hit" in group for group in stack[1:])
    assert all(v >= 0 for group in stack for v in group.values())
