"""README.md's settings and passes tables are generated from the core's (scripts/settings_doc.py)."""
import importlib.util
import os

from parallax_core import PASSES, SETTINGS

REPO = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))


def _settings_doc():
    spec = importlib.util.spec_from_file_location("settings_doc", os.path.join(REPO, "scripts", "settings_doc.py"))
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def test_readme_settings_tables_are_current():
    doc = _settings_doc()
    with open(os.path.join(REPO, "README.md"), encoding="utf-8") as f:
        text = f.read()
    assert doc.updated(text, SETTINGS, PASSES) == text, \
        "README.md's settings tables are out of date: run scripts/settings_doc.py"


def test_the_section_has_a_line_for_every_row():
    lines = _settings_doc().section(SETTINGS, PASSES).splitlines()
    for row in SETTINGS:
        assert sum(line.startswith(f"| `{row.name}` | ") for line in lines) == \
            1 + sum(p.name == row.name for p in PASSES), row.name
    for p in PASSES:
        assert any(line.startswith(f"| `{p.name}` | {p.label} |") for line in lines), p.name
