"""Finds the native core (the ``parallax_core`` package).

Blender 4.2+ installs the wheels listed in blender_manifest.toml itself. Legacy installs
(Blender 3.4 to 4.1) get the same wheels unpacked once into ``_site/`` next to this file: the
core's and pyoidn's (whose OpenImageDenoise library the denoiser loads where Blender has none).
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
    oidn = sorted(glob.glob(os.path.join(_HERE, "wheels", "pyoidn-*-py3-none-*.whl")))[-1:]
    with open(wheels[-1], "rb") as f:
        digest = hashlib.sha256(f.read())
    for path in oidn:  # 90 MB: its name and size identify it
        digest.update(f"{os.path.basename(path)}:{os.path.getsize(path)}".encode())
    marker = os.path.join(_SITE, f"unpacked-{digest.hexdigest()[:16]}")
    if not os.path.exists(marker):  # new wheels replace what older ones unpacked
        shutil.rmtree(_SITE, ignore_errors=True)
        os.makedirs(_SITE)
        for path in wheels[-1:] + oidn:
            with zipfile.ZipFile(path) as wheel:
                wheel.extractall(_SITE)
        _restore_modes(_SITE)
        open(marker, "w").close()
    if _SITE not in sys.path:
        sys.path.append(_SITE)
    return True


def _restore_modes(folder):
    """zipfile drops file modes: OIDN's libraries load either way, its tools need +x."""
    for root, _, files in os.walk(folder):
        if os.path.basename(root) == "bin":
            for name in files:
                os.chmod(os.path.join(root, name), 0o755)


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
