"""Finds the native core (the ``parallax_core`` package).

Blender 4.2+ installs the wheel listed in blender_manifest.toml itself. Legacy installs
(Blender 3.4 to 4.1) get the same wheel unpacked once into ``_site/`` next to this file.
The add-on's settings and passes come from the core's tables, so registering loads it;
without it, registering fails with the ImportError below, which says what to install.
"""
import glob
import hashlib
import os
import shutil
import sys
import zipfile

_HERE = os.path.dirname(os.path.abspath(__file__))
_SITE = os.path.join(_HERE, "_site")


def _python_tag():
    return f"cp{sys.version_info.major}{sys.version_info.minor}"


def _unpack_bundled_wheel():
    wheels = sorted(glob.glob(os.path.join(_HERE, "wheels", f"parallax_core-*-{_python_tag()}-*.whl")))
    if not wheels:
        return False
    with open(wheels[-1], "rb") as f:
        digest = hashlib.sha256(f.read()).hexdigest()[:16]
    marker = os.path.join(_SITE, f"unpacked-{digest}")
    if not os.path.exists(marker):  # a new wheel replaces what an older one unpacked
        shutil.rmtree(_SITE, ignore_errors=True)
        os.makedirs(_SITE)
        with zipfile.ZipFile(wheels[-1]) as wheel:
            wheel.extractall(_SITE)
        open(marker, "w").close()
    if _SITE not in sys.path:
        sys.path.append(_SITE)
    return True


def load():
    """Returns the ``parallax_core`` module or raises ImportError saying what to install."""
    try:
        import parallax_core.scene
        return parallax_core
    except ImportError as first_error:
        if _unpack_bundled_wheel():
            import parallax_core.scene
            return parallax_core
        raise ImportError(
            f"Parallax's native core (parallax_core) is not installed for this Blender's Python "
            f"{sys.version_info.major}.{sys.version_info.minor}: install the extension zip built by "
            f"`make extension` ({first_error})") from first_error
