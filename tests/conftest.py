import glob
import os
import subprocess
import sys

import pytest

# tests/helpers.py is imported as a plain module.
sys.path.insert(0, os.path.dirname(__file__))
REPO = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))


@pytest.fixture(scope="session")
def core_wheel(tmp_path_factory):
    """The parallax_core wheel (cp311), built like `make extension` builds it."""
    out = tmp_path_factory.mktemp("wheels")
    subprocess.run([sys.executable, "-m", "pip", "wheel", "-q", "--no-build-isolation", "--no-deps",
                    "-w", str(out), REPO], check=True, timeout=600)
    (path,) = glob.glob(str(out / "parallax_core-*-cp311-*.whl"))
    return path
