"""Khronos validation (issue 9): PARALLAX_VALIDATION=1 runs the core under
VK_LAYER_KHRONOS_validation with synchronization validation, the core records what the layer
reports, and the suite's fixture (tests/conftest.py) fails a test that produced any of it."""
import json
import os
import shutil
import subprocess
import sys
import textwrap

TESTS = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))

SELF_TEST = """
import json, parallax_core as pc
from parallax_core import _native
enabled = pc.validation_enabled()
_native._validation_self_test()
print(json.dumps({"enabled": enabled, "messages": pc.validation_messages()}))
"""


def run_python(code, validation):
    env = {**os.environ, "PARALLAX_VALIDATION": validation}
    out = subprocess.run([sys.executable, "-c", code], env=env, capture_output=True, text=True, timeout=300)
    assert out.returncode == 0, out.stderr
    return json.loads(out.stdout.strip().splitlines()[-1])


def test_layer_reports_core_and_synchronization_errors():
    got = run_python(SELF_TEST, "1")
    assert got["enabled"]
    ids = " ".join(got["messages"])
    assert "VUID-VkBufferCreateInfo-usage-requiredbitmask" in ids  # core validation
    assert "SYNC-HAZARD-WRITE-AFTER-WRITE" in ids  # synchronization validation
    assert len(got["messages"]) == 2


def test_no_layer_unless_asked():
    got = run_python(SELF_TEST, "0")
    assert not got["enabled"] and got["messages"] == []


def test_fixture_fails_a_test_with_validation_messages(tmp_path):
    shutil.copy(os.path.join(TESTS, "conftest.py"), tmp_path / "conftest.py")
    (tmp_path / "test_case.py").write_text(textwrap.dedent("""
        import parallax_core as pc
        from parallax_core import _native, scenes

        def test_clean():
            s = pc.Session(8, 8)
            s.update(scenes.cornell_box(8, 8))
            s.render(1)

        def test_mistake():
            _native._validation_self_test()
    """))
    env = {**os.environ, "PARALLAX_VALIDATION": "1"}
    out = subprocess.run([sys.executable, "-m", "pytest", "-q", "-p", "no:cacheprovider", str(tmp_path)],
                         cwd=tmp_path, env=env, capture_output=True, text=True, timeout=300)
    assert out.returncode == 1, out.stdout + out.stderr
    # test_clean passes; test_mistake passes its call and errors in the fixture's teardown.
    assert "2 passed, 1 error" in out.stdout, out.stdout
    assert "test_mistake" in out.stdout and "SYNC-HAZARD-WRITE-AFTER-WRITE" in out.stdout


def test_the_suite_runs_under_the_layer_unless_turned_off():
    import parallax_core as pc

    # tests/conftest.py asks for the layer unless the run set PARALLAX_VALIDATION=0.
    assert pc.validation_enabled() == (os.environ["PARALLAX_VALIDATION"] != "0")
