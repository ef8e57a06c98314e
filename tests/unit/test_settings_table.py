"""The settings and passes tables (parallax_core.SETTINGS, PASSES): every layer of the core
package reads them, and the core validates every value against its row."""
import dataclasses
import math
import re

import numpy as np
import pytest

import parallax_core as pc
from parallax_core.cli import parse_params
from parallax_core.exr import layer_channels

TYPES = {"bool": bool, "int": int, "float": float, "enum": str}
PANELS = {"", "sampling", "light_paths", "film", "lights", "denoising", "ic", "adrrs", "guiding"}


def test_rows_are_well_formed():
    names = [s.name for s in pc.SETTINGS]
    assert len(names) == len(set(names))
    techniques = [s.technique for s in pc.SETTINGS]
    assert techniques == sorted(techniques, key=["base", "ic", "adrrs", "guiding"].index)  # table order
    for s in pc.SETTINGS:
        assert type(s.default) is TYPES[s.type], s
        assert s.panel in PANELS and s.label and s.tooltip, s
        if s.type in ("int", "float"):
            assert type(s.min) is type(s.max) is TYPES[s.type] and s.min <= s.default <= s.max, s
        else:
            assert s.min is None and s.max is None, s
        assert bool(s.items) == (s.type == "enum"), s
        if s.type == "enum":
            assert s.default in [i[0] for i in s.items] and all(len(i) == 3 and all(i) for i in s.items)
    # Each technique's switch is the first row of its table: the bool named as the technique,
    # or for Russian roulette and splitting the enum rrs, off by default at its item "off".
    assert pc.TECHNIQUES == ("ic", "adrrs", "guiding")
    assert [pc.technique_switch(t).name for t in pc.TECHNIQUES] == ["ic", "rrs", "guiding"]
    for t in pc.TECHNIQUES:
        switch = pc.technique_switch(t)
        assert switch.technique == t and switch == next(s for s in pc.SETTINGS if s.technique == t)
        assert switch.type == "bool" or (switch.type == "enum" and switch.default == "off" == switch.items[0][0])
        assert not pc.setting_on(switch.name, switch.default) and pc.setting_off(switch.name) == switch.default
    assert [i[0] for i in pc.setting("rrs").items] == ["off", "adrrs", "ears"]
    assert pc.setting_on("rrs", "ears") and pc.setting_on("rrs", "adrrs") and pc.setting_on("ic", True)
    with pytest.raises(ValueError, match="unknown technique 'base'"):
        pc.technique_switch("base")
    # The engine's rows (no core field): sampling's, the viewport's adaptive sampling and denoising's
    # (parallax_core.denoise).
    assert [s.name for s in pc.SETTINGS if not s.core] == [
        "samples", "time_limit", "use_preview_adaptive_sampling", "preview_adaptive_threshold",
        "use_denoising", "denoising_input_passes", "denoising_prefilter",
        "denoising_quality", "use_preview_denoising", "preview_denoising_start_sample",
        "preview_denoising_input_passes", "preview_denoising_prefilter", "preview_denoising_quality"]


def test_render_params_come_from_the_core_rows():
    fields = {f.name: f for f in dataclasses.fields(pc.RenderParams)}
    core = [s for s in pc.SETTINGS if s.core]
    assert list(fields) == [s.name for s in core]
    defaults = dataclasses.asdict(pc.RenderParams())
    for s in core:
        assert defaults[s.name] == s.default and type(defaults[s.name]) is type(s.default), s.name
    assert pc.METHODS == tuple(i[0] for i in pc.setting("method").items)


def test_setting_lookup():
    assert pc.setting("ic_accuracy").technique == "ic"
    with pytest.raises(ValueError, match="unknown setting 'bogus' .*ic_accuracy"):
        pc.setting("bogus")


@pytest.mark.parametrize("row", [s for s in pc.SETTINGS if s.core], ids=lambda s: s.name)
def test_the_core_checks_every_row(row):
    """Every value is checked in the core against its row: type, range, enum name."""
    ok = pc.RenderParams(**{row.name: row.default})
    ok.validate()
    bad = {"bool": [2, "yes", 0.5], "enum": ["bogus", 1], "int": [1.5, "3"], "float": ["x", math.nan, math.inf]}
    values = list(bad[row.type])
    if row.type in ("int", "float"):
        values += [row.min - 1, row.max + 1]
    for value in values:
        with pytest.raises(ValueError, match=re.escape(row.name) + " must be") as e:
            pc.RenderParams(**{row.name: value}).validate()
        assert f"got {value!r}" in str(e.value) or f"got {value}" in str(e.value)
        if row.type in ("int", "float"):  # the message names the range
            assert "[%.10g, %.10g]" % (row.min, row.max) in str(e.value)
    if row.type in ("int", "float"):  # the ends of the range pass
        for value in (row.min, row.max):
            params = pc.RenderParams(**{row.name: value})
            # a relation: max_regions >= 2^region_splits
            if row.name == "guiding_max_regions" and value < 8:
                params.guiding_region_splits = 0
            if row.name == "guiding_region_splits":
                params.guiding_max_regions = 2**value
            if row.name == "guiding_lobes_phase" and value == row.max:
                continue  # a relation of its own: -1 or [0, 1)
            params.validate()


def test_set_params_takes_enums_by_name_and_relations_are_checked():
    s = pc.Session(4, 4)
    s.set_params(method="nee", mis_heuristic="balance", adrrs_estimate="image", guiding_fit="cpu")
    assert s.params.method == "nee" and s.params.guiding_fit == "cpu"
    with pytest.raises(ValueError, match="guiding_max_regions must be at least 2\\^guiding_region_splits"):
        s.set_params(guiding_region_splits=5, guiding_max_regions=16)
    with pytest.raises(ValueError, match="preview frames use no technique: turn ic off"):
        s.set_params(preview=True, ic=True)
    with pytest.raises(ValueError, match="preview frames use no technique: turn ic, rrs off"):
        s.set_params(preview=True, ic=True, rrs="ears")
    with pytest.raises(TypeError, match="unknown render parameter"):
        s.set_params(bounces=3)


def test_rrs_and_its_synonym_adrrs():
    """rrs = off | adrrs | ears; adrrs (ADRRS' switch before it) stays a synonym: True sets
    rrs adrrs, False sets it off, anything but a boolean is a ValueError naming adrrs."""
    s = pc.Session(4, 4)
    for value in ("adrrs", "ears", "off"):
        s.set_params(rrs=value)
        assert s.params.rrs == value
    for value, rrs in ((True, "adrrs"), (False, "off"), (1, "adrrs"), (0, "off"), (np.bool_(True), "adrrs")):
        s.set_params(adrrs=value)
        assert s.params.rrs == rrs and not hasattr(s.params, "adrrs"), value
    assert "adrrs" not in dataclasses.asdict(s.params)
    for value in ("yes", "adrrs", 2, 0.5, None):
        with pytest.raises(ValueError, match=r"^adrrs must be a boolean .*got " + re.escape(repr(value))):
            s.set_params(adrrs=value)
    with pytest.raises(ValueError, match="^rrs must be one of off, adrrs, ears, got 'bogus'"):
        s.set_params(rrs="bogus")
    assert s.params.rrs == "adrrs"  # a bad value changes nothing
    s.set_params(adrrs=True, rrs="adrrs")  # the same: fine
    with pytest.raises(ValueError, match="adrrs=True sets rrs='adrrs', which contradicts rrs='ears'"):
        s.set_params(adrrs=True, rrs="ears")
    assert pc.resolve_synonyms({"adrrs": False, "seed": 3}) == {"rrs": "off", "seed": 3}
    assert pc.synonym("seed", 3) == ("seed", 3)
    # --set: the synonym comes back as its setting, a later pair overriding an earlier one.
    assert parse_params(["adrrs=1"]) == {"rrs": "adrrs"} and parse_params(["adrrs=off"]) == {"rrs": "off"}
    assert parse_params(["adrrs=on", "rrs=ears"]) == {"rrs": "ears"}
    assert parse_params(["rrs=ears", "adrrs=0"]) == {"rrs": "off"}
    with pytest.raises(ValueError, match="'adrrs=maybe': expected 1/0"):
        parse_params(["adrrs=maybe"])
    with pytest.raises(ValueError, match="or a synonym: adrrs"):
        parse_params(["bogus=1"])


def test_cli_parses_by_row_type():
    for s in pc.SETTINGS:
        text = {"bool": "on", "enum": s.default, "int": str(s.default), "float": repr(s.default)}[s.type]
        assert parse_params([f"{s.name}={text}"]) == {s.name: True if s.type == "bool" else s.default}


def test_passes_table():
    names = [p.name for p in pc.PASSES]
    labels = [p.label for p in pc.PASSES]
    assert len(set(names)) == len(names) and len(set(labels)) == len(labels)
    assert names[:5] == ["combined", "depth", "normal", "albedo", "ray_depth"]
    assert pc.Session.pass_names() == names
    settings = {s.name: s for s in pc.SETTINGS}
    for p in pc.PASSES:
        assert len(p.channel_ids) == p.channels and p.description, p
        # A technique's passes are switched by the technique's switch; the engine's Noisy Image by
        # Use Denoising.
        switch = (pc.technique_switch(p.technique).name if p.technique != "base" else "") if p.core else "use_denoising"
        assert p.setting == switch and (p.setting == "" or settings[p.setting].type in ("bool", "enum")), p
        assert layer_channels(p.name, p.channels) == [f"{p.label}.{c}" for c in p.channel_ids]
    assert [p.name for p in pc.PASSES if not p.core] == ["noisy_image"]
    s = pc.Session(3, 2)
    from parallax_core import scenes
    s.update(scenes.cornell_box(3, 2))
    s.render(1)
    for p in pc.PASSES:
        if p.core:
            assert s.read(p.name).shape == (2, 3, p.channels), p.name
        else:  # made by the engine (the denoiser), not the film
            with pytest.raises(ValueError, match="made by the engine"):
                s.read(p.name)
    assert set(s.read_all()) == {p.name for p in pc.PASSES if p.core}
