"""Cycles' light paths (issue 36): bounce budgets per kind of scattering and the sample clamps,
against closed forms. In a closed box of Lambertian walls that all emit E and reflect albedo a,
a path tracer without roulette carries exactly E a^j after j bounces, so every sample of a pixel
is the same truncated or clamped sum."""
import numpy as np
import pytest

import parallax_core as pc
from parallax_core import scenes
from parallax_core.scene import Material

from helpers import batches, means_agree, render

A, E = 0.5, 1.0  # walls' albedo and emission


def box_mean(method="pt", spp=64, **params):
    scene = scenes.closed_emitter_box(albedo=A, emission=E, width=8, height=8)
    img, _ = render(scene, method, spp=spp, max_depth=64, depth_leeway=0, rr_start_depth=0, **params)
    return float(img.mean())


def truncated(bounces):
    """E (1 + a + ... + a^(bounces + 1)): a budget of k bounces still counts the emission the
    k-th bounce's ray finds, as Cycles (and Max Bounces) do."""
    return E * sum(A ** j for j in range(bounces + 2))


@pytest.mark.parametrize("budget", [0, 2])
def test_diffuse_budget_truncates_the_series(budget):
    assert box_mean(diffuse_bounces=budget) == pytest.approx(truncated(budget), rel=1e-4)


def test_other_budgets_do_not_count_diffuse_bounces():
    # Lambertian bounces are diffuse: the glossy and transmission budgets never bind here.
    assert box_mean(glossy_bounces=0, transmission_bounces=0) == pytest.approx(truncated(63), rel=1e-4)


def test_glossy_budget_counts_glossy_bounces():
    # The same box with rough metal walls: the glossy budget ends its paths, the diffuse one does not.
    scene = scenes.closed_emitter_box(albedo=A, emission=E, width=8, height=8)
    scene.materials = [Material("conductor", (A, A, A), roughness=0.5, emission=(E, E, E), emission_strength=1.0)]
    common = dict(max_depth=64, depth_leeway=0, rr_start_depth=0, n_batches=4, spp=64)
    unlimited = batches(scene, "pt", **common)
    no_diffuse = batches(scene, "pt", diffuse_bounces=0, **common)
    no_glossy = batches(scene, "pt", glossy_bounces=0, **common)
    assert means_agree(unlimited.means, no_diffuse.means)[0]
    # No glossy bounce after the first: E plus what one bounce finds, at most E (1 + a).
    assert no_glossy.mean.mean() <= E * (1 + A) * 1.001 < unlimited.mean.mean()


def test_indirect_clamp_scales_samples_down_to_three_times_the_setting():
    # Bounce j adds E a^j per channel, 3 E a^j over RGB. Direct light (seen, or found by the
    # first bounce's ray) is not clamped; later bounces over 3 x 0.1 are scaled to it.
    expected = E * (1 + A) + sum(min(E * A ** j, 0.1) for j in range(2, 65))
    assert box_mean(sample_clamp_indirect=0.1) == pytest.approx(expected, rel=1e-4)


def test_direct_clamp_limits_only_direct_light():
    expected = min(E, 0.2) + min(E * A, 0.2) + sum(E * A ** j for j in range(2, 65))
    assert box_mean(sample_clamp_direct=0.2) == pytest.approx(expected, rel=1e-4)


def test_clamps_bias_mis_downwards_only():
    clamped = box_mean("mis", spp=128, sample_clamp_indirect=0.1, sample_clamp_direct=0.2)
    assert clamped < 0.95 * box_mean("mis", spp=128)


def test_cycles_defaults_and_the_unbiased_pins():
    p = pc.RenderParams()
    assert (p.max_depth, p.diffuse_bounces, p.glossy_bounces, p.transmission_bounces) == (12, 4, 4, 12)
    assert (p.sample_clamp_direct, p.sample_clamp_indirect) == (0.0, 10.0)
    assert (p.pixel_filter_type, p.filter_width) == ("BLACKMAN_HARRIS", 1.5)
    unbiased = pc.RenderParams(**pc.UNBIASED_LIGHT_PATHS)
    assert min(unbiased.diffuse_bounces, unbiased.glossy_bounces, unbiased.transmission_bounces) >= 1024
    assert unbiased.sample_clamp_direct == unbiased.sample_clamp_indirect == 0.0
    with pytest.raises(ValueError, match="filter_width"):
        pc.RenderParams(filter_width=0.0).validate()


def test_limits_that_cannot_bind_leave_the_image_bit_for_bit():
    # A pipeline carries the budgets and clamps only where the settings can bind them
    # (LIGHT_PATH_LIMITS). Carried but idle (a glossy budget in a Lambertian box, a clamp no
    # sample reaches) they change nothing: the same image as the pipeline without them.
    scene = scenes.cornell_box(16, 16)
    plain, _ = render(scene, "mis", spp=16)
    idle, _ = render(scene, "mis", spp=16, glossy_bounces=0, transmission_bounces=0, sample_clamp_indirect=1e5)
    assert np.array_equal(plain, idle)
