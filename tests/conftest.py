import glob
import os
import subprocess
import sys

import pytest

# tests/helpers.py is imported as a plain module.
sys.path.insert(0, os.path.dirname(__file__))
REPO = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))

# Khronos validation (issue 9) for the whole run: the process's Vulkan instance is created
# once, on first use, so the layer is asked for before any test runs (subprocesses inherit
# it). PARALLAX_VALIDATION=0 turns it off (a machine without vulkan-validationlayers).
os.environ.setdefault("PARALLAX_VALIDATION", "1")
# Mesa's shader cache in one part for every process of the run, not only for the core's (which
# asks for it itself): Blender 3.4's OpenGL under Xvfb (tests/viewport) is Mesa's too, shares
# CI's cache directory, and with Mesa's default 50 parts trims the part it writes to (ours) to
# 21 MB, evicting pipelines that later tests then compile cold again.
os.environ.setdefault("MESA_DISK_CACHE_DATABASE_NUM_PARTS", "1")
# Pipelines that carry every light type, vertex normals, UVs and conductors whatever the scene
# holds (FEATURES_FOLDED): a cold run compiles 75 variants instead of 164, and the images are
# bit for bit the same (tests/render/test_pipeline_variants.py). Renders specialise for exactly
# the scene's features: folded, lavapipe's frames take 4-10% longer.
os.environ.setdefault("PARALLAX_SCENE_FEATURES", "folded")


@pytest.fixture(autouse=True)
def no_validation_messages():
    """Fails a test during which the validation layer reported a warning or an error (in this
    process: tests that render through parallax_core or in-process bpy)."""
    if os.environ.get("PARALLAX_VALIDATION", "0") in ("", "0") or "parallax_core" not in sys.modules:
        yield
        return
    import parallax_core as pc

    pc.validation_messages(clear=True)
    yield
    messages = pc.validation_messages(clear=True)
    if messages:
        pytest.fail(f"{len(messages)} Vulkan validation message(s), the first:\n" + "\n".join(messages[:3]),
                    pytrace=False)


@pytest.fixture(autouse=True)
def compile_log_marks_the_test(request):
    """With PARALLAX_COMPILE_LOG (the core's log of the pipelines it creates, a line each with
    its process and parent), a line "test PID NODEID" before each test: the pipelines after it
    with that process or parent are the test's."""
    path = os.environ.get("PARALLAX_COMPILE_LOG")
    if path:
        with open(path, "a") as f:
            f.write(f"test {os.getpid()} {request.node.nodeid}\n")
    yield


@pytest.fixture(scope="session")
def core_wheel(tmp_path_factory):
    """The parallax_core wheel (cp311), built like `make extension` builds it."""
    out = tmp_path_factory.mktemp("wheels")
    subprocess.run([sys.executable, "-m", "pip", "wheel", "-q", "--no-build-isolation", "--no-deps",
                    "-w", str(out), REPO], check=True, timeout=600)
    (path,) = glob.glob(str(out / "parallax_core-*-cp311-*.whl"))
    return path
