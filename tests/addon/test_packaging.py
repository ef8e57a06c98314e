"""Packaging: the extension zip installs and renders in Blender 5.0 (bpy), and the same
add-on folder works as a legacy add-on in Debian's Blender 3.4."""
import glob
import os
import shutil
import subprocess
import sys

from pathlib import Path

import pytest
from blender_helpers import SCENES
from helpers import install_addon_copy

RENDER_AND_REPORT = """
import bpy
scene = bpy.context.scene
scene.render.engine = "PARALLAX"
scene.render.resolution_x, scene.render.resolution_y = 24, 16
scene.parallax.samples = 2
bpy.ops.render.render()
final = __import__(ENGINE_MODULE + ".engine.final", fromlist=["final"])
import parallax_core
print("REPORT", final.last_report.samples, final.last_report.errors, parallax_core.__file__)
"""


def test_extension_zip_installs_and_renders(tmp_path, core_wheel):
    import bpy  # noqa: F401  (bpy's extension builder ships with it)

    addon = Path(install_addon_copy(tmp_path, core_wheel))
    manifest = (addon / "blender_manifest.toml").read_text()
    assert f'"./wheels/{os.path.basename(core_wheel)}"' in manifest  # the manifest names this wheel
    scripts = bpy.utils.system_resource("SCRIPTS")
    builder = os.path.join(scripts, "addons_core", "bl_pkg", "cli", "blender_ext.py")
    subprocess.run([sys.executable, builder, "build", "--source-dir", str(addon), "--output-dir",
                    str(tmp_path)], check=True, capture_output=True, timeout=300)
    (package,) = glob.glob(str(tmp_path / "parallax-*.zip"))
    script = tmp_path / "install.py"
    script.write_text(
        "import bpy\n"
        f"bpy.ops.extensions.package_install_files(filepath={package!r}, repo='user_default',"
        " enable_on_install=True)\n"
        f"bpy.ops.wm.open_mainfile(filepath={os.path.join(SCENES, 'cornell_box.blend')!r})\n"
        "ENGINE_MODULE = 'bl_ext.user_default.parallax'\n" + RENDER_AND_REPORT)
    env = dict(os.environ, BLENDER_USER_RESOURCES=str(tmp_path / "user"))
    r = subprocess.run([sys.executable, str(script)], capture_output=True, text=True, env=env,
                       timeout=300)
    assert "REPORT 2 []" in r.stdout, r.stdout + r.stderr
    site = glob.glob(str(tmp_path / "user" / "extensions" / ".local" / "lib" / "python3.*" /
                         "site-packages" / "parallax_core" / "_native*.so"))
    assert site, "Blender did not install the bundled wheel"


@pytest.mark.skipif(shutil.which("blender") is None, reason="Debian's blender is not installed "
                    "(make setup installs it)")
def test_legacy_addon_in_blender_34(tmp_path, core_wheel):
    addons = tmp_path / "scripts" / "addons"
    addons.mkdir(parents=True)
    install_addon_copy(addons, core_wheel)
    script = tmp_path / "legacy.py"
    script.write_text(
        "import addon_utils, bpy\n"
        "assert addon_utils.enable('parallax', default_set=True) is not None\n"
        "ENGINE_MODULE = 'parallax'\n" + RENDER_AND_REPORT +
        "addon_utils.disable('parallax')\n"
        "assert addon_utils.enable('parallax') is not None\n"
        "print('RE-ENABLED')\n")
    env = dict(os.environ, BLENDER_USER_SCRIPTS=str(tmp_path / "scripts"))
    env.pop("PYTHONPATH", None)
    r = subprocess.run(["blender", "-b", "--factory-startup", "--python-exit-code", "1", "--python",
                        str(script)], capture_output=True, text=True, env=env, timeout=300)
    out = r.stdout + r.stderr
    assert r.returncode == 0 and "REPORT 2 []" in out and "RE-ENABLED" in out, out
    # The core came from the bundled wheel, unpacked next to the add-on.
    assert str(addons / "parallax" / "_site" / "parallax_core") in out, out
