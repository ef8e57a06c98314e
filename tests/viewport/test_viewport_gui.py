"""The viewport in a real Blender window: Debian's Blender 3.4 GUI under Xvfb (llvmpipe),
driven by gui_driver.py, checked through `xwd -root` screenshots.

One Blender session renders blender_scenes/cornell_box (built by Blender 3.4 itself, which
cannot read files saved by Blender 5) in a Rendered viewport, moves the tall box and orbits;
another starts an F12 render and cancels it with Esc sent by xdotool.
"""
import json
import shutil
import subprocess
import time
from pathlib import Path

import gui as gui_tools
import numpy as np
import pytest
from xwd import read_xwd

TOOLS = gui_tools.TOOLS
pytestmark = pytest.mark.skipif(not all(shutil.which(t) for t in TOOLS),
                                reason=f"needs {', '.join(TOOLS)} (make setup installs them)")
WIDTH, HEIGHT = 640, 400  # small for CI time (960x600 cost 40% more); the test waits on events, not on speed


@pytest.fixture(scope="module")
def gui(tmp_path_factory, core_wheel):
    session = gui_tools.BlenderGui(str(tmp_path_factory.mktemp("gui")), core_wheel, (WIDTH, HEIGHT))
    yield session
    session.close()


def _finish(proc, out, timeout=1000, exit_codes=(0,)):
    try:
        log, _ = proc.communicate(timeout=timeout)
    except subprocess.TimeoutExpired:
        proc.kill()
        log, _ = proc.communicate()
        pytest.fail(f"Blender did not quit (hung?):\n{log[-3000:]}")
    result_file = out / "result.json"
    assert result_file.exists(), f"no result (exit {proc.returncode}):\n{log[-3000:]}"
    result = json.loads(result_file.read_text())
    assert not result["errors"], "\n".join(result["errors"]) + log[-3000:]
    assert proc.returncode in exit_codes, log[-3000:]
    assert "Traceback" not in log, log[-3000:]
    return result, log


def _viewport_image(result, name):
    """The 3D viewport's pixels of a screenshot (the Rendered image), row 0 at the top."""
    image = read_xwd(result["shots"][name]).astype(np.float32) / 255.0
    x, y, w, h = result["region"]
    win_h = image.shape[0]
    return image[win_h - (y + h):win_h - y, x:x + w]


def _camera_frame(image):
    """The part of a camera-view screenshot inside the camera frame (outside the box the
    world is black)."""
    lit = np.flatnonzero(image.mean(axis=(0, 2)) > 0.02)
    return image[:, lit[0]:lit[-1] + 1]


def _box_mean(image, fx0, fx1, fy0, fy1):
    h, w = image.shape[:2]
    return image[int(fy0 * h):int(fy1 * h), int(fx0 * w):int(fx1 * w)].reshape(-1, 3).mean(axis=0)


def _noise(image):
    """Mean absolute difference of horizontally adjacent pixels (of the middle half)."""
    h, w = image.shape[:2]
    middle = image[h // 4:3 * h // 4, w // 4:3 * w // 4]
    return float(np.abs(np.diff(middle, axis=1)).mean())


def test_rendered_viewport_refines_and_follows_edits(gui):
    proc, out = gui.start("cornell_box", "viewport")
    result, log = _finish(proc, Path(out))
    early, converged = _viewport_image(result, "early"), _viewport_image(result, "converged")
    # Red wall on the left, green wall on the right of the camera view.
    frame = _camera_frame(converged)
    left, right = _box_mean(frame, 0.02, 0.1, 0.3, 0.7), _box_mean(frame, 0.9, 0.98, 0.3, 0.7)
    # (sRGB values under the yellowish light: the green wall is only somewhat greener than red)
    assert left[0] > 2 * left[1] and right[1] > 1.2 * right[0], (left, right)
    assert left[0] > right[0] and right[1] > left[1], (left, right)
    assert _noise(converged) < 0.8 * _noise(early)
    moved, orbited = _viewport_image(result, "moved"), _viewport_image(result, "orbited")
    assert np.abs(moved - converged).mean() > 0.01  # the tall box moved
    assert np.abs(orbited - moved).mean() > 0.02   # the view turned
    assert result["samples_per_second"] > 0
    assert result["workers_alive_after_solid"] == 0
    latencies = {tuple(parts): seconds for parts, seconds in result["latencies"]}
    assert ("instances",) in latencies and ("camera",) in latencies, latencies
    print(f"edit -> first frame: {latencies}; {result['samples_per_second']:.1f} samples/s")


def test_escape_cancels_an_f12_render_within_a_second(gui):
    proc, out = gui.start("cornell_box", "cancel")
    out = Path(out)
    deadline = time.time() + 120
    while not (out / "rendering").exists():
        assert proc.poll() is None and time.time() < deadline, proc.communicate()[0][-3000:]
        time.sleep(0.1)
    env = gui.env
    subprocess.run(["xdotool", "mousemove", str(WIDTH // 2), str(HEIGHT // 2)], env=env, check=True)
    (out / "escape_sent").write_text(repr(time.time()))
    subprocess.run(["xdotool", "key", "Escape"], env=env, check=True)
    # Blender exits with status 1 after a user break (Esc sets G.is_break).
    result, _ = _finish(proc, out, exit_codes=(0, 1))
    assert result["cancelled"] and result["cancel_seconds"] < 1.0, result
    # Blender's job then ends (its display work is slow on llvmpipe) and the UI goes on.
    assert not result["still_rendering"] and result["job_seconds"] < 5.0, result
    assert result["responsive"]
    print(f"Esc -> render stopped {result['cancel_seconds']:.2f} s, job ended {result['job_seconds']:.2f} s")


def test_denoising_in_blender_34_finds_the_bundled_pyoidn(gui):
    """Debian's Blender 3.4 has no OIDN: the panel, the viewport's denoise thread and F12 use the
    library of the pyoidn wheel the add-on carries (unpacked into _site/ with the core)."""
    proc, out = gui.start("cornell_box", "denoise")
    result, log = _finish(proc, Path(out))
    assert result["denoiser"] == [["OpenImageDenoise from pyoidn", "INFO"]], result["denoiser"]
    viewport = result["viewport"]
    assert viewport["message"] is None and viewport["denoised_frames"] >= 1 and viewport["samples"] >= 2, viewport
    f12 = result["f12"]
    assert not f12["errors"] and f12["samples"] == 4 and f12["denoised"], f12
    assert "from pyoidn" in f12["message"], f12
