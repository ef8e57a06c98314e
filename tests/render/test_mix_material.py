"""Mix chains (Material.mix_next / mix_weight): a stochastic choice of one BSDF per hit must
converge to the weighted mixture of the BSDFs, for every integrator; emission comes from the
head material only; the native layer rejects broken chains on its own."""
import dataclasses

import numpy as np
import pytest

import parallax_core as pc
from parallax_core import scenes
from parallax_core.scene import Material

from helpers import batches, means_agree, render, z_scores

METHODS = ("pt", "nee", "mis")

C1, C2, W = (0.9, 0.15, 0.2), (0.1, 0.6, 0.8), 0.3  # mixed: (0.34, 0.465, 0.62)
# A three-link chain: RED1 (0.5), then RED2 (0.5 * 0.4), then RED3 (0.5 * 0.6).
RED1, RED2, RED3, W_RED1, W_RED2 = (0.9, 0.1, 0.0), (0.2, 0.0, 0.6), (0.5, 0.5, 0.1), 0.5, 0.4


def _blend(a, b, w):
    return tuple(w * x + (1.0 - w) * y for x, y in zip(a, b))


RED_BLEND = _blend(RED1, _blend(RED2, RED3, W_RED2), W_RED1)


def _interior(s):
    """Pixels fully on the furnace sphere (neighbours on it too: no partial coverage)."""
    on = s.read("depth")[..., 0] < 1e9
    inner = on.copy()
    inner[1:-1, 1:-1] &= on[:-2, 1:-1] & on[2:, 1:-1] & on[1:-1, :-2] & on[1:-1, 2:]
    inner[[0, -1], :] = False
    inner[:, [0, -1]] = False
    return inner


def _mixed_cornell(size=16):
    """Cornell box whose white surfaces and the light are two-diffuse mixes and whose red
    wall is a three-diffuse chain, and the blended-colour reference: the same scene with
    single diffuse materials of colour w1 c1 + (1-w1) (w2 c2 + ...). Materials reached
    through a chain carry emission that must be ignored."""
    mixed = scenes.cornell_box(size, size)
    ref = scenes.cornell_box(size, size)
    white, red, green, light = mixed.materials
    mixed.materials = [
        Material("diffuse", C1, mix_next=4, mix_weight=W, name="white-mix"),
        Material("diffuse", RED1, mix_next=5, mix_weight=W_RED1, name="red-mix"),
        green,
        # An emitter that also reflects: its emission (head) counts, half of the hits scatter
        # off the chain's tail.
        Material("emission", emission=light.emission, mix_next=6, mix_weight=0.5, name="light-mix"),
        Material("diffuse", C2, emission=(50.0, 50.0, 50.0), name="white-tail"),
        Material("diffuse", RED2, emission=(50.0, 0.0, 0.0), mix_next=7, mix_weight=W_RED2,
                 name="red-middle"),
        Material("diffuse", (0.8, 0.8, 0.8), emission=(9.0, 9.0, 9.0), name="light-tail"),
        Material("diffuse", RED3, emission=(0.0, 50.0, 0.0), name="red-tail"),
    ]
    ref.materials = [
        Material("diffuse", _blend(C1, C2, W), name="white"),
        Material("diffuse", RED_BLEND, name="red"),
        green,
        Material("diffuse", (0.4, 0.4, 0.4), emission=light.emission, name="light"),
    ]
    return mixed, ref


@pytest.fixture(scope="module")
def session16():
    return pc.Session(16, 16)


@pytest.mark.parametrize("method, spp", [("pt", 512), ("mis", 128)])
def test_two_diffuse_mix_equals_blended_diffuse(session16, method, spp):
    mixed, ref = _mixed_cornell(16)
    s = session16
    res = {}
    for name, sc in (("mix", mixed), ("ref", ref)):
        s.update(sc)
        res[name] = batches(sc, method, n_batches=6, spp=spp, session=s, max_depth=6)
    z = z_scores(res["mix"].images, res["ref"].images, k=4)
    assert np.abs(z).max() < 5.0, f"max |z| = {np.abs(z).max():.2f}"
    ok, ma, mb, se = means_agree(res["mix"][3], res["ref"][3])
    assert ok, f"mix {ma:.4f} vs blended {mb:.4f} (standard error {se:.4f})"


def test_mix_albedo_pass_converges_to_blend(session16):
    # The albedo pass comes from the chosen lobe: its expectation is the blended colour, the
    # reference's (deterministic) albedo.
    s = session16
    albedo = {}
    for name, sc in zip(("mix", "ref"), _mixed_cornell(16)):
        s.update(sc)
        # Every parameter pinned (a one-pixel box filter among them): the module's session
        # keeps what an earlier test set, and run first, a wider filter blurs the pure pixels.
        s.set_params(**{**dataclasses.asdict(pc.RenderParams()), **pc.UNBIASED_LIGHT_PATHS, "method": "mis",
                        "samples_per_frame": 64, "seed": 3, "max_depth": 0, "rr_start_depth": 0})
        s.reset()
        s.render(4)
        albedo[name] = s.read("albedo")
    white = np.all(np.abs(albedo["ref"] - _blend(C1, C2, W)) < 1e-4, axis=-1)
    red = np.all(np.abs(albedo["ref"] - RED_BLEND) < 1e-4, axis=-1)
    assert white.sum() > 100 and red.sum() > 4
    # Per pixel: 256 samples of a two-valued colour (difference <= 0.8): se <= 0.025.
    assert np.abs(albedo["mix"][white] - albedo["ref"][white]).max() < 0.15
    np.testing.assert_allclose(albedo["mix"][white].mean(0), _blend(C1, C2, W), atol=0.01)
    np.testing.assert_allclose(albedo["mix"][red].mean(0), RED_BLEND, atol=0.03)
    np.testing.assert_allclose(albedo["mix"].mean((0, 1)), albedo["ref"].mean((0, 1)), atol=0.01)


def _diffuse_conductor_cornell(size=16, weight=0.3, roughness=0.35):
    """Cornell box with floor, back wall and boxes a (weight) diffuse + (1 - weight) rough
    gold mix. The ceiling stays white diffuse: glossy lobes at grazing angles right next to
    the light (2 cm below it) make NEE alone too heavy-tailed to compare at these counts."""
    sc = scenes.cornell_box(size, size)
    white = sc.materials[0]
    sc.materials = [
        Material("diffuse", white.base_color, mix_next=4, mix_weight=weight, name="plastic-ish"),
        *sc.materials[1:],
        Material("conductor", (0.95, 0.8, 0.55), roughness=roughness, name="gold"),
        white,
    ]
    ceiling = sc.meshes[1]
    assert ceiling.name == "ceiling"
    ceiling.material_indices = np.full(len(ceiling.indices), 5)
    return sc


def test_diffuse_conductor_mix_pt_nee_mis_agree(session16):
    sc = _diffuse_conductor_cornell(16)
    s = session16
    s.update(sc)
    res = {m: batches(sc, m, n_batches=6, spp=spp, session=s, max_depth=5)
           for m, spp in (("pt", 512), ("nee", 128), ("mis", 128))}
    for a, b in (("pt", "mis"), ("nee", "mis"), ("pt", "nee")):
        z = z_scores(res[a].images, res[b].images, k=4)
        assert np.abs(z).max() < 5.0, f"{a} vs {b}: max |z| = {np.abs(z).max():.2f}"
        ok, ma, mb, se = means_agree(res[a][3], res[b][3])
        assert ok, f"{a} vs {b}: image means {ma:.4f} vs {mb:.4f} (standard error {se:.4f})"


def test_mix_is_linear_in_the_lobes_for_direct_light(session16):
    # Direct light only (max_depth 0): the image is linear in the first vertex's BSDF, so
    # mix(w) = w * all-diffuse + (1 - w) * all-conductor, pixel by pixel. The references use
    # each material on its own (no chain), so this also checks that the pipeline carries the
    # code of materials only reachable through a chain (the conductor behind a diffuse head).
    s = session16
    w = 0.3
    res = {}
    for name in ("mix", "diffuse", "conductor"):
        sc = _diffuse_conductor_cornell(16, w)
        if name == "diffuse":
            sc.materials[0] = Material("diffuse", sc.materials[0].base_color)
        elif name == "conductor":
            sc.materials[0] = sc.materials[4]
        s.update(sc)
        res[name] = batches(sc, "mis", n_batches=6, spp=128, session=s, max_depth=0)
    # Batch b of the combination combines batch b of each lobe's (independent) renders.
    expect = w * res["diffuse"].images + (1 - w) * res["conductor"].images
    z = z_scores(res["mix"].images, expect, k=4)
    assert np.abs(z).max() < 5.0, f"max |z| = {np.abs(z).max():.2f}"
    combo = w * res["diffuse"][3] + (1 - w) * res["conductor"][3]
    ok, ma, mb, se_mean = means_agree(res["mix"][3], combo)
    assert ok, f"mix {ma:.4f} vs linear combination {mb:.4f} (standard error {se_mean:.4f})"
    # The lobes' images differ by far more than the noise, so a wrong weighting would show: most
    # blocks beyond the threshold. (With 6 batches a side the scores grow only slowly past 10, as
    # the normal deviate of a t's tail with about 10 degrees of freedom. Measured: 77% beyond 5.)
    assert (np.abs(z_scores(res["diffuse"].images, res["conductor"].images, k=4)) > 5.0).mean() > 0.5


def test_three_link_chain_renders_finite(session16):
    sc = scenes.cornell_box(16, 16)
    sc.materials = [
        Material("diffuse", (0.7, 0.7, 0.7), mix_next=4, mix_weight=0.4),
        *sc.materials[1:],
        Material("conductor", (0.9, 0.9, 0.9), roughness=0.2, mix_next=5, mix_weight=0.5),
        Material("dielectric", (1.0, 1.0, 1.0), roughness=0.0, ior=1.5),
    ]
    s = session16
    s.update(sc)
    for method in METHODS:
        img, _ = render(sc, method, spp=32, session=s, seed=1, max_depth=6)
        assert np.isfinite(img).all(), method
        assert img.mean() > 0.05, method
        assert np.isfinite(s.read("albedo")).all()


@pytest.mark.parametrize(
    "chain",
    [
        # white diffuse (0.5) + perfect white mirror (0.5)
        [Material("diffuse", (1.0, 1.0, 1.0), mix_next=1, mix_weight=0.5),
         Material("conductor", (1.0, 1.0, 1.0), roughness=0.0)],
        # diffuse (0.4) -> mirror (0.6 * 0.5) -> smooth glass (0.6 * 0.5)
        [Material("diffuse", (1.0, 1.0, 1.0), mix_next=1, mix_weight=0.4),
         Material("conductor", (1.0, 1.0, 1.0), roughness=0.0, mix_next=2, mix_weight=0.5),
         Material("dielectric", (1.0, 1.0, 1.0), roughness=0.0, ior=1.5)],
    ],
    ids=["diffuse+mirror", "diffuse+mirror+glass"],
)
def test_white_furnace_lossless_chain(chain):
    # Every lobe is lossless, so is any mixture of them: each sphere pixel converges to the
    # world's radiance 1. A mix that lost or added energy (weights not summing to one) fails.
    sc = scenes.furnace_sphere(0.5, 16, 16)
    sc.materials = chain
    s = pc.Session(16, 16)
    s.update(sc)
    for method in METHODS:
        mean, _, _, batch_means, _ = batches(sc, method, n_batches=4, spp=64, session=s, max_depth=64,
                                             depth_leeway=64, rr_start_depth=0)
        inner = _interior(s)
        assert inner.sum() > 20
        se = np.std(batch_means, ddof=1) / np.sqrt(len(batch_means))
        assert abs(mean[inner].mean() - 1.0) <= 0.01 + 5 * se, (method, mean[inner].mean(), se)


def test_mix_draws_its_random_number_only_at_mix_heads():
    # Hits on materials without a chain take no extra random number even when the pipeline
    # has the mix walk compiled in (FEATURE_MIX): a furnace sphere with a mixed triangle hidden
    # inside it renders bit for bit what the plain sphere renders. An unused mix material
    # changes nothing either.
    plain = scenes.furnace_sphere(0.5, 16, 16)
    img_plain, s = render(plain, "mis", spp=16, seed=5, max_depth=8)
    hidden = scenes.furnace_sphere(0.5, 16, 16)
    hidden.meshes.append(scenes.quad([(-0.05, -0.05, 0), (0.05, -0.05, 0), (0.05, 0.05, 0),
                                      (-0.05, 0.05, 0)], 1, "hidden"))
    hidden.materials = [*hidden.materials,
                        Material("diffuse", (0.2, 0.9, 0.2), mix_next=2, mix_weight=0.5),
                        Material("conductor", roughness=0.3)]
    s.update(hidden)
    img_hidden, _ = render(hidden, "mis", spp=16, session=s, seed=5, max_depth=8)
    assert np.array_equal(img_plain, img_hidden)
    unused = scenes.furnace_sphere(0.5, 16, 16)
    unused.materials = [*unused.materials, Material("conductor", mix_next=0, mix_weight=0.5)]
    s.update(unused)
    img_unused, _ = render(unused, "mis", spp=16, session=s, seed=5, max_depth=8)
    assert np.array_equal(img_plain, img_unused)
    # Whereas mixing the sphere itself (weight 1: the same BSDF) shifts the random stream.
    mixed = scenes.furnace_sphere(0.5, 16, 16)
    mixed.materials = [Material("diffuse", (0.5, 0.5, 0.5), mix_next=1, mix_weight=1.0),
                       Material("conductor")]
    s.update(mixed)
    img_mixed, _ = render(mixed, "mis", spp=16, session=s, seed=5, max_depth=8)
    assert not np.array_equal(img_plain, img_mixed)


# ---- native validation (a hand-made dict bypasses SceneData's checks) -------------------

def _flat_with_mix(next_, weight):
    sc = scenes.cornell_box(8, 8)
    sc.materials = [*sc.materials, Material("conductor"), Material("diffuse")]
    flat = sc.flatten()
    flat["material_mix_next"] = np.asarray(next_, np.int32)
    flat["material_mix_weight"] = np.asarray(weight, np.float32)
    return flat


@pytest.mark.parametrize(
    "next_, weight, message",
    [
        ([-1, -1, -1, -1, 5, 4], [1] * 6, r"material 4: mix chain has a cycle"),
        ([-1, -1, -1, -1, 4, -1], [1] * 6, r"material 4: mix chain has a cycle"),
        ([0, -1, -1, -1, 9, -1], [1] * 6, r"material 4: mix_next 9 out of range \(6 materials\)"),
        ([-1, -1, -1, -1, -2, -1], [1] * 6, r"material 4: mix_next -2 out of range"),
        ([-1, -1, -1, -1, 5, -1], [1, 1, 1, 1, np.nan, 1], r"material 4: mix_weight is NaN"),
        ([-1] * 5, [1] * 5, r"material_mix_\* arrays differ in length"),
    ],
    ids=["cycle", "self-cycle", "out-of-range", "negative", "nan-weight", "length"],
)
def test_native_rejects_bad_chains(session16, next_, weight, message):
    with pytest.raises(ValueError, match=message):
        session16.update(_flat_with_mix(next_, weight))


def test_native_chain_length_limit_and_defaults(session16):
    from parallax_core.scene import MIX_CHAIN_MAX

    sc = scenes.cornell_box(8, 8)
    n = MIX_CHAIN_MAX
    sc.materials = [*sc.materials, *[Material("diffuse") for _ in range(n + 1)]]
    flat = sc.flatten()
    K = len(flat["material_type"])
    nxt = np.full(K, -1, np.int32)
    nxt[4:4 + n] = np.arange(5, 5 + n)  # 4 -> 5 -> ... -> 4 + n: n + 1 materials
    flat["material_mix_next"], flat["material_mix_weight"] = nxt, np.full(K, 0.5, np.float32)
    with pytest.raises(ValueError, match=f"material 4: mix chain of {n + 1} materials"):
        session16.update(flat)
    nxt[4] = -1  # now n materials: allowed
    session16.update(flat)
    # Arrays from before mix chains (no mix keys) still load; a clamped weight renders.
    flat = scenes.cornell_box(16, 16).flatten()
    del flat["material_mix_next"], flat["material_mix_weight"]
    session16.update(flat)
    flat["material_mix_next"] = np.array([2, -1, -1, -1], np.int32)
    flat["material_mix_weight"] = np.array([7.0, 1, 1, 1], np.float32)  # clamped to 1
    session16.update(flat)
    img, _ = render(scenes.cornell_box(16, 16), "mis", spp=8, session=session16)
    assert np.isfinite(img).all()
