"""Cycles' Filter Glossy (`blur_glossy`, issue 36): after a bounce the path was unlikely to take
(its smallest BSDF pdf so far, min_ray_pdf, below blur_glossy), glossy and glass lobes are
blurred to GGX alpha >= sqrt(1 - min_ray_pdf / blur_glossy) / 2 (integrator.glsl blur_glossy).
It trades a small bias for less noise in caustics; its bias vanishes as blur_glossy goes to 0."""
import numpy as np
import pytest

import parallax_core as pc
from parallax_core import scenes
from parallax_core.scene import Material

from helpers import batches, render, same_render, z_scores


@pytest.fixture(scope="module")
def device_type():
    return pc.Session(4, 4).device_type


def glass_sphere_box(width=32, height=32):
    """The Cornell box with a smooth glass sphere on its floor: the floor's caustic reaches the
    camera only through a diffuse bounce and then the glass."""
    scene = scenes.cornell_box(width, height)
    scene.materials.append(Material("dielectric", (1.0, 1.0, 1.0), roughness=0.0, ior=1.5, name="glass"))
    glass = len(scene.materials) - 1
    scene.meshes.append(scenes.uv_sphere((0.35, -0.3, 0.45), 0.4, segments=32, rings=16, material=glass))
    return scene


def test_cycles_default_and_the_unbiased_pin():
    assert pc.RenderParams().blur_glossy == 1.0
    assert pc.UNBIASED_LIGHT_PATHS["blur_glossy"] == 0.0
    assert pc.setting("blur_glossy").label == "Filter Glossy"


def test_it_lowers_the_caustics_noise_for_a_small_bias():
    scene = glass_sphere_box()
    sharp = batches(scene, "mis", n_batches=8, spp=64)
    blurred = batches(scene, "mis", n_batches=8, spp=64, blur_glossy=1.0)
    # The sum over pixels of each pixel's variance: 0.56x on lavapipe.
    assert (blurred.se ** 2).sum() < 0.75 * (sharp.se ** 2).sum()
    # Biased (the blurred glass spreads the caustic), but by little: -1.3% of the mean on lavapipe.
    bias = blurred.mean.mean() / sharp.mean.mean() - 1.0
    assert 0.0005 < abs(bias) < 0.05


def test_its_bias_vanishes_as_blur_glossy_goes_to_zero():
    # Common random numbers (the same seeds with and without the blur) measure the bias itself:
    # the paths differ only after a blurred vertex. On lavapipe: -1.42% (se 0.07%) at 1,
    # -0.57% at 0.3, -0.004% at 0.03, -0.0004% at 0.01.
    scene = glass_sphere_box()
    sharp = batches(scene, "mis", n_batches=8, spp=64, seed_base=100)

    def bias(blur):
        d = batches(scene, "mis", n_batches=8, spp=64, blur_glossy=blur, seed_base=100).means - sharp.means
        return d.mean() / sharp.means.mean(), d.std(ddof=1) / np.sqrt(d.size) / sharp.means.mean()

    (b1, se1), (b03, _), (b001, _) = bias(1.0), bias(0.3), bias(0.01)
    assert b1 < -5.0 * se1  # measurable at the default
    assert abs(b1) > abs(b03) > abs(b001)
    assert abs(b001) < 1e-4
    # Block by block, the slightly blurred image agrees with the unblurred one.
    slight = batches(scene, "mis", n_batches=8, spp=64, blur_glossy=0.01)
    assert np.abs(z_scores(slight.images, sharp.images, k=4)).max() < 5.0


def test_paths_without_a_blurry_bounce_are_not_blurred(device_type):
    # A glass sphere under a white world: camera rays and delta bounces leave min_ray_pdf at
    # infinity, so nothing blurs.
    scene = scenes.furnace_sphere(width=16, height=16)
    scene.materials = [Material("dielectric", (1.0, 1.0, 1.0), roughness=0.0, ior=1.5, name="glass")]
    sharp, _ = render(scene, "mis", spp=16)
    blurred, _ = render(scene, "mis", spp=16, blur_glossy=10.0)
    assert same_render(sharp, blurred, device_type)


def test_lobes_rougher_than_the_blur_are_left_alone(device_type):
    # The blur reaches alpha 0.5 at most (roughness 0.707): rough metal walls at 0.75 keep theirs.
    scene = scenes.closed_emitter_box(albedo=0.5, emission=1.0, width=8, height=8)
    scene.materials = [Material("conductor", (0.5, 0.5, 0.5), roughness=0.75, emission=(1.0, 1.0, 1.0),
                                emission_strength=1.0)]
    sharp, _ = render(scene, "mis", spp=16)
    blurred, _ = render(scene, "mis", spp=16, blur_glossy=10.0)
    assert same_render(sharp, blurred, device_type)
    smoother = [Material("conductor", (0.5, 0.5, 0.5), roughness=0.3, emission=(1.0, 1.0, 1.0),
                         emission_strength=1.0)]
    scene.materials = smoother
    sharp, _ = render(scene, "mis", spp=16)
    blurred, _ = render(scene, "mis", spp=16, blur_glossy=10.0)
    assert not np.array_equal(sharp, blurred)


@pytest.mark.parametrize("technique", [dict(rrs="adrrs"), dict(rrs="ears"), dict(ic=True)],
                         ids=["adrrs", "ears", "ic"])
def test_techniques_render_with_it(technique):
    # ADRRS' and EARS' split copies and the cache's hemisphere paths carry the path's min_ray_pdf.
    img, s = render(glass_sphere_box(16, 16), "mis", spp=16, blur_glossy=1.0, **technique)
    assert np.isfinite(img).all() and img.mean() > 0.0
