"""Running Debian's Blender GUI under Xvfb with the add-on installed in a scratch HOME: used
by the GUI tests and bench/viewport_latency.py."""
import os
import subprocess
import sys
import time

HERE = os.path.dirname(os.path.abspath(__file__))
REPO = os.path.dirname(os.path.dirname(HERE))
sys.path.insert(0, os.path.dirname(HERE))  # tests/helpers.py
from helpers import install_addon_copy  # noqa: E402

TOOLS = ("blender", "Xvfb", "xwd", "xdotool")


def _free_display():
    for n in range(90, 200):
        if not os.path.exists(f"/tmp/.X11-unix/X{n}") and not os.path.exists(f"/tmp/.X{n}-lock"):
            return n
    raise RuntimeError("no free X display number")


class BlenderGui:
    """A scratch HOME with the add-on (and its core wheel), scenes built by this Blender, and
    an Xvfb display of ``size``."""

    def __init__(self, root, wheel, size, scenes=("cornell_box",)):
        self.root, self.size = root, size
        scripts = os.path.join(root, "scripts", "addons")
        os.makedirs(scripts)
        os.makedirs(os.path.join(root, "home"))
        install_addon_copy(scripts, wheel)
        self.env = dict(os.environ, HOME=os.path.join(root, "home"),
                        BLENDER_USER_SCRIPTS=os.path.join(root, "scripts"))
        self.env.pop("PYTHONPATH", None)
        # Blender 3.4 cannot read files saved by Blender 5: it builds its own copies.
        subprocess.run(["blender", "-b", "--factory-startup", "--python",
                        os.path.join(REPO, "blender_scenes", "build.py"), "--", *scenes, "--out", root],
                       env=self.env, check=True, capture_output=True, timeout=600)
        n = _free_display()
        self.xvfb = subprocess.Popen(["Xvfb", f":{n}", "-screen", "0", f"{size[0]}x{size[1]}x24",
                                      "-nolisten", "tcp"], stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
        deadline = time.time() + 20
        while not os.path.exists(f"/tmp/.X11-unix/X{n}"):
            if time.time() > deadline or self.xvfb.poll() is not None:
                raise RuntimeError("Xvfb did not start")
            time.sleep(0.1)
        self.env["DISPLAY"] = f":{n}"

    def start(self, scene, mode, tag=None):
        """Starts Blender on ``scene`` with gui_driver.py in ``mode``; returns (process, out dir),
        OUT_DIR named after ``tag`` (default: the mode)."""
        out = os.path.join(self.root, f"{tag or mode}-{scene}")
        os.makedirs(out)
        proc = subprocess.Popen(
            ["blender", "--factory-startup", "-p", "0", "0", str(self.size[0]), str(self.size[1]),
             "--no-window-focus", os.path.join(self.root, scene + ".blend"), "--python",
             os.path.join(HERE, "gui_driver.py"), "--", out, mode],
            env=self.env, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
        return proc, out

    def close(self):
        self.xvfb.terminate()
        self.xvfb.wait(10)
