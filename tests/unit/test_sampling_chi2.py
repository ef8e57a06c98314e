"""Chi-square goodness-of-fit tests of the shader sampling routines (DESIGN "Tests", tier 1).

Each routine of shaders/lib/{bsdf,lights}.glsl is run through shaders/tests/sampling_test.comp
(``Session.test_sampling``): sampled directions are binned on a (theta, phi) grid -- over the
whole sphere, or over a cap around a light in a rotated frame -- and compared with the counts
expected from integrating the routine's own pdf (eval mode) over each bin, as in Mitsuba's
and pbrt's chi2 tests. The integration is a midpoint rule on a sub-grid, each sub-cell
weighted by its exact solid angle, with sub-cells next to a jump of the pdf redone finer
(light outlines, the horizon), and sub-rows split at known jumps along a theta circle.
Cells with fewer than 5 expected samples are pooled. A test passes when p > ALPHA, a
Sidak-corrected 1 % level over all chi-square tests in this file. The integral of the pdf
must also match the fraction of samples the routine accepted.

Besides the chi-square tests: sampler pdf == eval pdf and weight == eval / pdf for every BSDF
sample; for lights, a BSDF ray along a light sample sees the radiance and pdf that NEE
reported (eval mode uses the integrator's own MIS functions); light selection proportional
to power (the power CDF) and through the light tree; spherical-triangle sampling of close
emitters (solid angle 1/omega in float64, sub-triangle counts, slivers, grazing views, both
sides of the threshold) and area sampling of far ones; radiance and delta-light values in Cycles'
units; the irradiance of a sphere and a sun light and the integral of an environment map.
Everything is seeded (PARALLAX_CHI2_SEED shifts all seeds): the same build gives the same
p-values, and over seeds they are uniform (checked over 16 seeds x 35 tests).
"""
from __future__ import annotations

import math
import os

import numpy as np
import pytest

import parallax_core as pc
from parallax_core import scenes
from parallax_core.scene import (Light, Material, Mesh, SceneData, World,
                                 direction_to_equirectangular, equirectangular_to_direction)

TEST_DIFFUSE, TEST_CONDUCTOR, TEST_DIELECTRIC, TEST_LIGHT, TEST_IC_HEMISPHERE = 0, 1, 2, 3, 4
IC_THETA, IC_PHI = 10, 20  # shaders/shared/techniques.h: the thesis' strata
IC_THETA_CONSISTENT, IC_PHI_CONSISTENT = 6, 12  # ... consistent mode's
EVAL = 16                 # routine + EVAL: evaluate at given directions
N = 300_000               # samples per chi-square test
DISTANT = 1e29            # sample distance at or above this: a light at infinity
CHI2_TESTS = 66           # upper bound on the chi-square tests below (Sidak correction)
ALPHA = 1.0 - (1.0 - 0.01) ** (1.0 / CHI2_TESTS)
# Added to every seed; set PARALLAX_CHI2_SEED to check the p-values are uniform over seeds.
SEED = int(os.environ.get("PARALLAX_CHI2_SEED", "0"))


# ---- statistics (no scipy) ----------------------------------------------------------------

def gammaincc(a: float, x: float) -> float:
    """Regularised upper incomplete gamma Q(a, x) (Numerical Recipes: series / Lentz)."""
    if x <= 0.0:
        return 1.0
    log_front = -x + a * math.log(x) - math.lgamma(a)
    if x < a + 1.0:  # series for P(a, x)
        ap, term = a, 1.0 / a
        total = term
        for _ in range(100_000):
            ap += 1.0
            term *= x / ap
            total += term
            if abs(term) < abs(total) * 1e-15:
                break
        return max(0.0, 1.0 - total * math.exp(log_front))
    tiny = 1e-300
    b = x + 1.0 - a
    c, d = 1.0 / tiny, 1.0 / b
    h = d
    for i in range(1, 100_000):
        an = -i * (i - a)
        b += 2.0
        d = an * d + b
        d = d if abs(d) > tiny else tiny
        c = b + an / c
        c = c if abs(c) > tiny else tiny
        d = 1.0 / d
        delta = d * c
        h *= delta
        if abs(delta - 1.0) < 1e-15:
            break
    return math.exp(log_front) * h


def chi2_sf(stat: float, dof: int) -> float:
    return gammaincc(0.5 * dof, 0.5 * stat)


def chi2_pooled(observed, expected, min_expected=5.0):
    """Pearson's statistic with cells of expected count < min_expected pooled into one
    (merged into the smallest regular cell if the pool itself stays below min_expected).
    Returns (statistic, degrees of freedom, p-value)."""
    obs = np.asarray(observed, np.float64).ravel()
    exp = np.asarray(expected, np.float64).ravel()
    low = exp < min_expected
    o, e = obs[~low], exp[~low]
    po, pe = obs[low].sum(), exp[low].sum()
    if po > 0 or pe > 0:
        if pe >= min_expected or len(e) == 0:
            o, e = np.append(o, po), np.append(e, max(pe, 1e-12))
        else:
            k = int(np.argmin(e))
            o[k] += po
            e[k] += pe
    stat = float(((o - e) ** 2 / e).sum())
    dof = len(e) - 1
    assert dof >= 1, "too few cells for a chi-square test"
    return stat, dof, chi2_sf(stat, dof)


# ---- directional histograms ---------------------------------------------------------------

def frame_around(axis):
    """Rows x, y, z of an orthonormal frame with z = axis."""
    z = np.asarray(axis, np.float64)
    z = z / np.linalg.norm(z)
    helper = np.array([1.0, 0.0, 0.0]) if abs(z[0]) < 0.9 else np.array([0.0, 1.0, 0.0])
    x = np.cross(helper, z)
    x /= np.linalg.norm(x)
    return np.stack([x, np.cross(z, x), z])


class SphereGrid:
    """theta x phi bins in a frame (theta from the frame's z); theta edges are given, phi is
    uniform over (-pi, pi]. Directions beyond the last theta edge fall into an extra cell
    whose expected count is 0 (the caller chooses a cap that holds the pdf's support)."""

    def __init__(self, theta_edges, n_phi=32, frame=None):
        self.theta = np.asarray(theta_edges, np.float64)
        self.n_theta, self.n_phi = len(self.theta) - 1, n_phi
        self.frame = np.eye(3) if frame is None else np.asarray(frame, np.float64)
        self.full = self.theta[-1] >= math.pi

    @classmethod
    def sphere(cls, n_theta=16, n_phi=32):
        return cls(np.linspace(0.0, math.pi, n_theta + 1), n_phi)

    @classmethod
    def cone(cls, axis, cos_max, n_inside=12, n_outside=3, n_phi=24):
        """Cap around ``axis`` whose theta edges put the cone edge acos(cos_max) on a bin
        edge, plus n_outside empty bins beyond it (to catch samples outside the cone)."""
        t = math.acos(min(max(cos_max, -1.0), 1.0))
        edges = np.linspace(0.0, t, n_inside + 1)
        edges = np.append(edges, t + (t / n_inside) * np.arange(1, n_outside + 1))
        return cls(np.minimum(edges, math.pi), n_phi, frame_around(axis))

    @classmethod
    def bounding(cls, p, points, margin=1.15, n_theta=12, n_phi=24):
        """Cap from p around every point of ``points`` (an emitter's outline)."""
        d = np.asarray(points, np.float64) - np.asarray(p, np.float64)
        d /= np.linalg.norm(d, axis=1, keepdims=True)
        axis = d.mean(axis=0)
        axis /= np.linalg.norm(axis)
        t = min(math.pi, margin * float(np.arccos(np.clip(d @ axis, -1.0, 1.0)).max()))
        return cls(np.linspace(0.0, t, n_theta + 1), n_phi, frame_around(axis))

    def index(self, dirs):
        """Cell of each direction; n_theta * n_phi = outside the cap."""
        d = np.asarray(dirs, np.float64)
        d = d / np.linalg.norm(d, axis=1, keepdims=True)
        local = d @ self.frame.T
        theta = np.arccos(np.clip(local[:, 2], -1.0, 1.0))
        phi = np.arctan2(local[:, 1], local[:, 0])
        it = np.searchsorted(self.theta, theta, side="right") - 1
        it = np.where(theta == self.theta[-1], self.n_theta - 1, it)  # closed last edge
        ip = np.clip(((phi + math.pi) / (2.0 * math.pi) * self.n_phi).astype(np.int64), 0, self.n_phi - 1)
        cell = it * self.n_phi + ip
        return np.where((it < 0) | (it >= self.n_theta), self.n_theta * self.n_phi, cell)

    def histogram(self, dirs):
        return np.bincount(self.index(dirs), minlength=self.n_theta * self.n_phi + 1).astype(np.float64)

    def _directions(self, theta, phi):
        st = np.sin(theta)
        local = np.stack([st * np.cos(phi), st * np.sin(phi), np.cos(theta)], axis=-1)
        return (local.reshape(-1, 3) @ self.frame).astype(np.float32)

    def integrate(self, pdf, nsub=16, breaks=(), refine=8, jump=0.1):
        """Integral of pdf(directions) over each cell (+ 0 for the outside cell).

        Midpoint rule on nsub x nsub sub-cells per cell, each weighted by its exact solid
        angle. Sub-cells where the pdf jumps (a 4-neighbour differs by more than ``jump``,
        relatively) straddle an edge of the pdf's support or a steep lobe: they are redone
        with refine x refine points. ``breaks`` are polar angles where the pdf jumps along a
        whole theta circle: sub-rows are split there, as an edge aligned with the sub-grid
        makes the midpoint rule's error systematic instead of cancelling."""
        t0, t1 = self.theta[:-1], self.theta[1:]
        sub = (t0[:, None] + (t1 - t0)[:, None] * (np.arange(nsub + 1) / nsub)[None, :]).ravel()
        inside = [b for b in breaks if self.theta[0] < b < self.theta[-1]]
        edges = np.unique(np.concatenate([sub, np.asarray(inside, np.float64)]))
        ts = 0.5 * (edges[:-1] + edges[1:])
        row_bin = np.searchsorted(self.theta, ts, side="right") - 1
        C = self.n_phi * nsub
        dphi = 2.0 * math.pi / C
        ps = -math.pi + dphi * (np.arange(C) + 0.5)
        tt, pp = np.meshgrid(ts, ps, indexing="ij")
        values = np.asarray(pdf(self._directions(tt, pp)), np.float64).reshape(len(ts), C)
        assert np.all(np.isfinite(values)) and np.all(values >= 0.0), "pdf not finite / negative"
        cell = values * ((np.cos(edges[:-1]) - np.cos(edges[1:])) * dphi)[:, None]
        # sub-cells next to a jump: recompute with refine x refine points
        flag = np.zeros(values.shape, bool)
        for a, b, axis in ((values[:, 1:], values[:, :-1], 1), (np.roll(values, 1, 1), values, None),
                           (values[1:], values[:-1], 0)):
            j = np.abs(a - b) > jump * np.maximum(a, b)
            if axis is None:  # phi wraps around
                flag |= j | np.roll(j, -1, 1)
            elif axis == 1:
                flag[:, 1:] |= j
                flag[:, :-1] |= j
            else:
                flag[1:] |= j
                flag[:-1] |= j
        ri, ci = np.nonzero(flag)
        if len(ri):
            k = (np.arange(refine) + 0.5) / refine
            e0, e1 = edges[ri], edges[ri + 1]
            ft = e0[:, None, None] + (e1 - e0)[:, None, None] * k[None, :, None] + 0 * k[None, None, :]
            fp = (-math.pi + dphi * ci)[:, None, None] + dphi * k[None, None, :] + 0 * k[None, :, None]
            h = (e1 - e0)[:, None, None] / refine
            w = (np.cos(ft - 0.5 * h) - np.cos(ft + 0.5 * h)) * (dphi / refine)
            fv = np.asarray(pdf(self._directions(ft, fp)), np.float64).reshape(w.shape)
            assert np.all(np.isfinite(fv)) and np.all(fv >= 0.0), "pdf not finite / negative"
            cell[ri, ci] = (fv * w).sum(axis=(1, 2))
        rows = cell.reshape(len(ts), self.n_phi, nsub).sum(axis=2)
        mass = np.zeros((self.n_theta, self.n_phi))
        np.add.at(mass, row_bin, rows)
        self.refined = len(ri) / values.size
        return np.append(mass.ravel(), 0.0)


RESULTS: list[str] = []  # one line per chi-square test; printed at the end (pytest -s)


def assert_close_mostly(what, got, want, rtol=1e-3, loose=1e-2, fraction=1e-4):
    """|got - want| <= rtol |want| everywhere but for a `fraction` of the values, which
    must be within `loose`: near total internal reflection 1 - F cancels in float32, and the
    sampler's F (at the sampled microfacet) and eval's (at the half vector rebuilt from wi)
    differ by up to ~3e-3 for about 1 sample in 10^6."""
    got, want = np.asarray(got, np.float64), np.asarray(want, np.float64)
    rel = np.abs(got - want) / np.maximum(np.abs(want), 1e-12)
    worst = int(np.argmax(rel))
    assert rel.max() <= loose and (rel > rtol).mean() <= fraction, (
        f"{what}: {(rel > rtol).sum()} of {rel.size} differ by more than {rtol:g} "
        f"(worst {rel[worst]:.3g}: {got[worst]:.6g} vs {want[worst]:.6g})")


def check_fit(label, grid, dirs, n_total, pdf, nsub=16, breaks=(), integral_rtol=0.01):
    """Chi-square test of ``dirs`` (the accepted samples out of n_total draws) against
    ``pdf``; also checks that pdf integrates to the accepted fraction."""
    observed = grid.histogram(dirs)
    mass = grid.integrate(pdf, nsub, breaks)
    expected = mass * n_total
    accepted = len(dirs) / n_total
    integral = float(mass.sum())
    # Samples where the pdf is zero: a few may straddle an edge through float rounding.
    stray = float(observed[mass <= 0.0].sum())
    assert stray <= 2 + 1e-5 * n_total, f"{label}: {stray:.0f} samples where the pdf integrates to 0"
    sigma = math.sqrt(max(accepted * (1 - accepted), 1e-12) / n_total)
    assert abs(integral - accepted) <= integral_rtol * accepted + 4 * sigma, (
        f"{label}: pdf integrates to {integral:.5f} but {accepted:.5f} of the samples were accepted")
    stat, dof, p = chi2_pooled(observed, expected)
    RESULTS.append(f"{label:48s} chi2={stat:9.1f} dof={dof:4d} p={p:.4f} "
                   f"integral={integral:.5f} accepted={accepted:.5f}")
    assert p > ALPHA, f"{label}: chi2 = {stat:.1f} with {dof} dof, p = {p:.3g} <= {ALPHA:.3g}"
    return p


def check_multinomial(label, counts, probs):
    counts = np.asarray(counts, np.float64)
    probs = np.asarray(probs, np.float64)
    stat, dof, p = chi2_pooled(counts, probs / probs.sum() * counts.sum())
    RESULTS.append(f"{label:48s} chi2={stat:9.1f} dof={dof:4d} p={p:.4f}")
    assert p > ALPHA, f"{label}: counts {counts} vs probabilities {probs}: p = {p:.3g}"


@pytest.fixture(scope="module", autouse=True)
def _print_results():
    yield
    if RESULTS:
        print("\nchi-square results (alpha = %.2e):" % ALPHA)
        print("\n".join(RESULTS))


# ---- fixtures -----------------------------------------------------------------------------

@pytest.fixture(scope="module")
def session():
    s = pc.Session(8, 8)
    s.update(scenes.cornell_box(8, 8))  # the BSDF routines read no scene data
    return s


def lights_scene(lights=(), meshes=(), materials=(), world=None):
    return SceneData(meshes=list(meshes), materials=list(materials), lights=list(lights),
                     world=world or World(color=(0.0, 0.0, 0.0)))


def sample_lights(session, scene, p, n=N, seed=0, normal=False):
    """Light samples from p; normal: with a surface normal +z at p (the light tree's
    receiver term), else none."""
    session.update(scene)
    r = session.test_sampling(TEST_LIGHT, [*p, float(normal), 0.0], n, seed=seed)
    return r


def light_pdf(session, p, normal=False):
    """Eval mode: the summed light pdf of directions from p (triangle_light_pdf,
    analytic_light_hit and distant_radiance: what MIS uses when a BSDF ray hits a light)."""
    return lambda d: session.test_sampling(TEST_LIGHT + EVAL, [*p, float(normal), 0.0], len(d),
                                           directions=d)[:, 1, 1]


def check_light_hits(session, p, r, fraction=1e-4, normal=False):
    """With one light, a BSDF ray along a light sample's direction must see the radiance and
    pdf NEE reported (the sampler's pdf is the samples' density). A sample on the very edge
    of a light may miss it in eval: `fraction` of them may differ."""
    ok = r[:, 1, 2] > 0.5
    e = session.test_sampling(TEST_LIGHT + EVAL, [*p, float(normal), 0.0], int(ok.sum()), directions=r[ok, 0, :3])
    assert_close_mostly("light hit pdf vs sampler pdf", e[:, 1, 1], r[ok, 0, 3], loose=np.inf, fraction=fraction)
    assert_close_mostly("light hit radiance vs sampled radiance", e[:, 1, 0], r[ok, 1, 0], loose=np.inf,
                        fraction=fraction)


def smoothstep(x):
    x = min(max(x, 0.0), 1.0)
    return x * x * (3.0 - 2.0 * x)


def unit(v):
    v = np.asarray(v, np.float64)
    return v / np.linalg.norm(v)


def test_gammaincc():
    assert chi2_sf(3.841458820694124, 1) == pytest.approx(0.05, rel=1e-9)
    assert chi2_sf(7.0, 2) == pytest.approx(math.exp(-3.5), rel=1e-12)
    assert chi2_sf(124.342, 100) == pytest.approx(0.05, rel=1e-4)
    assert chi2_sf(135.807, 100) == pytest.approx(0.01, rel=1e-3)
    assert chi2_sf(3.0, 10) == pytest.approx(0.981424, rel=1e-5)
    for stat, dof in ((600.0, 480), (430.0, 480), (560.0, 500)):  # vs Wilson-Hilferty
        z = ((stat / dof) ** (1 / 3) - (1 - 2 / (9 * dof))) / math.sqrt(2 / (9 * dof))
        assert chi2_sf(stat, dof) == pytest.approx(0.5 * math.erfc(z / math.sqrt(2)), rel=0.02)
    assert chi2_sf(0.0, 5) == 1.0


# ---- BSDFs --------------------------------------------------------------------------------

def wo_at(deg, phi=0.7):
    t = math.radians(deg)
    return [math.sin(t) * math.cos(phi), math.sin(t) * math.sin(phi), math.cos(t)]


BSDF_CASES = (
    [("diffuse", TEST_DIFFUSE, a, 0.5, 1.5) for a in (20, 75)]
    + [("conductor", TEST_CONDUCTOR, a, r, 1.5) for r in (0.3, 0.6, 0.9) for a in (10, 45, 80)]
    + [("dielectric", TEST_DIELECTRIC, a, r, ior)
       for r in (0.4, 0.8) for ior in (1.5, 1.0 / 1.5) for a in (30, 70)]
)


def _case_id(c):
    return f"{c[0]}-wo{c[2]}-r{c[3]}" + (f"-ior{c[4]:.3g}" if c[0] == "dielectric" else "")


@pytest.mark.parametrize("case", BSDF_CASES, ids=_case_id)
def test_bsdf_chi2(session, case):
    name, routine, angle, rough, ior = case
    params = [*wo_at(angle), rough, ior]
    r = session.test_sampling(routine, params, N, seed=SEED + 100 + BSDF_CASES.index(case))
    ok = r[:, 1, 3] > 0.5
    if routine != TEST_DIELECTRIC:
        assert np.all(r[ok, 0, 2] > 0.0), "reflection below the surface"
    pdf = lambda d: session.test_sampling(routine + EVAL, params, len(d), directions=d)[:, 1, 1]
    # The pdf jumps at the horizon (a bin edge) and, for transmission, where the generalised
    # half vector -(wo + eta wi) turns horizontal: wi.z = -wo.z / eta.
    breaks = [math.acos(-params[2] / ior)] if routine == TEST_DIELECTRIC and params[2] < ior else []
    check_fit(_case_id(case), SphereGrid.sphere(16, 32), r[ok, 0, :3], N, pdf, breaks=breaks)


@pytest.mark.parametrize("case", BSDF_CASES, ids=_case_id)
def test_bsdf_pdf_and_weight_consistent(session, case):
    """Sampler pdf == eval pdf at the sampled direction; weight == eval / pdf; failed samples
    report pdf 0; everything finite and non-negative."""
    name, routine, angle, rough, ior = case
    params = [*wo_at(angle), rough, ior]
    r = session.test_sampling(routine, params, 50_000, seed=SEED + 5)
    assert np.all(np.isfinite(r))
    ok = r[:, 1, 3] > 0.5
    assert ok.mean() > 0.3
    assert np.all(r[~ok, 0, 3] == 0.0)
    pdf_s, weight, f_eval, pdf_e = r[ok, 0, 3], r[ok, 1, 0], r[ok, 1, 1], r[ok, 1, 2]
    assert np.all(pdf_s > 0.0) and np.all(pdf_e >= 0.0) and np.all(f_eval >= 0.0) and np.all(weight >= 0.0)
    assert_close_mostly("sampler pdf vs eval pdf", pdf_e, pdf_s)
    assert_close_mostly("weight vs f cos / pdf", weight, f_eval / pdf_s)
    # eval mode at the sampled directions (re-normalised) reproduces the in-shader evaluation
    e = session.test_sampling(routine + EVAL, params, int(ok.sum()), directions=r[ok, 0, :3])
    assert_close_mostly("eval mode pdf", e[:, 1, 1], pdf_e)
    assert_close_mostly("eval mode f cos", e[:, 1, 0], f_eval)
    if routine == TEST_DIFFUSE:  # Lambert with albedo 1: weight is exactly 1
        np.testing.assert_allclose(weight, 1.0, rtol=1e-6)
    else:  # energy conservation: G2 / G1 <= 1
        assert weight.max() <= 1.0 + 1e-5


# ---- Principled BSDF (shaders/lib/principled.glsl) -----------------------------------------

TEST_PRINCIPLED = 11  # types.h; the material follows the samples (PRINCIPLED_TEST_VEC4S vec4s)


def principled_constants(base=(0.8, 0.8, 0.8), roughness=0.5, specular_tint=(1, 1, 1), metallic=0.0,
                         coat_tint=(1, 1, 1), coat=0.0, sheen_tint=(1, 1, 1), sheen=0.0,
                         transmission=0.0, specular=0.5, coat_roughness=0.03, coat_ior=1.5,
                         sheen_roughness=0.5, multiscatter=True):
    return np.array([*base, roughness, *specular_tint, metallic, *coat_tint, coat, *sheen_tint, sheen,
                     transmission, specular, coat_roughness, coat_ior,
                     sheen_roughness, float(multiscatter), 0.0, 0.0], np.float32)


# One lobe alone (the others' weights are 0: black base, IOR Level 0 removes the specular
# layer), then mixtures of all of them, outside and inside (ior < 1: leaving the glass).
BLACK = (0.0, 0.0, 0.0)
PRINCIPLED_CASES = [
    ("diffuse", 40, 1.5, dict(specular=0.0)),
    ("specular", 60, 1.5, dict(base=BLACK, roughness=0.4)),
    ("metal", 50, 1.5, dict(base=(0.9, 0.6, 0.3), metallic=1.0, specular_tint=(0.8, 0.9, 1.0), roughness=0.5)),
    ("glass", 35, 1.5, dict(transmission=1.0, roughness=0.5, base=(0.9, 0.9, 0.7))),
    ("glass-inside", 35, 1.0 / 1.5, dict(transmission=1.0, roughness=0.5)),
    ("coat", 45, 1.5, dict(base=BLACK, specular=0.0, coat=1.0, coat_roughness=0.3)),
    ("sheen", 70, 1.5, dict(base=BLACK, specular=0.0, sheen=1.0, sheen_roughness=0.5)),
    ("all", 30, 1.5, dict(base=(0.8, 0.5, 0.3), metallic=0.3, transmission=0.3, coat=0.5,
                          coat_roughness=0.2, sheen=0.5, specular_tint=(1.0, 0.9, 0.8), roughness=0.45)),
    ("all-inside", 65, 1.0 / 1.45, dict(base=(0.6, 0.7, 0.8), metallic=0.2, transmission=0.6, coat=0.3,
                                        coat_roughness=0.4, sheen=0.3, roughness=0.6, specular=0.8)),
]


def _principled_run(session, case, n, seed, directions=None):
    name, angle, ior, kw = case
    routine = TEST_PRINCIPLED + (EVAL if directions is not None else 0)
    return session.test_sampling(routine, [*wo_at(angle), 0.0, ior], n, seed=seed, directions=directions,
                                 constants=principled_constants(**kw))


@pytest.mark.parametrize("case", PRINCIPLED_CASES, ids=lambda c: c[0])
def test_principled_chi2(session, case):
    """Each lobe's sampler, and the one-sample MIS mixture, against the pdf bsdf_eval reports."""
    name, angle, ior, kw = case
    r = _principled_run(session, case, N, SEED + 200 + PRINCIPLED_CASES.index(case))
    ok = r[:, 1, 3] > 0.5
    if kw.get("transmission", 0.0) == 0.0:
        assert np.all(r[ok, 0, 2] > 0.0), "reflection below the surface"
    pdf = lambda d: _principled_run(session, case, len(d), 0, directions=d)[:, 1, 1]
    wo_z = math.cos(math.radians(angle))
    breaks = [math.acos(-wo_z / ior)] if kw.get("transmission", 0.0) > 0.0 and wo_z < ior else []
    check_fit(f"principled-{name}", SphereGrid.sphere(16, 32), r[ok, 0, :3], N, pdf, breaks=breaks)


@pytest.mark.parametrize("case", PRINCIPLED_CASES, ids=lambda c: c[0])
def test_principled_pdf_and_weight_consistent(session, case):
    """Sampler pdf == eval pdf (the mixture's, as NEE + MIS uses it); weight == f cos / pdf."""
    r = _principled_run(session, case, 50_000, SEED + 7)
    assert np.all(np.isfinite(r))
    ok = r[:, 1, 3] > 0.5
    assert ok.mean() > 0.3
    pdf_s, weight, f_eval, pdf_e = r[ok, 0, 3], r[ok, 1, 0], r[ok, 1, 1], r[ok, 1, 2]
    assert np.all(pdf_s > 0.0) and np.all(f_eval >= 0.0) and np.all(weight >= 0.0)
    assert_close_mostly("sampler pdf vs eval pdf", pdf_e, pdf_s)
    assert_close_mostly("weight vs f cos / pdf", weight, f_eval / pdf_s)
    e = _principled_run(session, case, int(ok.sum()), 0, directions=r[ok, 0, :3])
    assert_close_mostly("eval mode pdf", e[:, 1, 1], pdf_e)
    assert_close_mostly("eval mode f cos", e[:, 1, 0], f_eval)


def principled_albedo(session, angle, ior=1.5, n=200_000, **kw):
    """Directional albedo (rgb mean) of the Principled BSDF: the mean sample weight."""
    r = _principled_run(session, ("albedo", angle, ior, kw), n, SEED + 11)
    return float(np.where(r[:, 1, 3] > 0.5, r[:, 1, 0], 0.0).mean())


@pytest.mark.parametrize("roughness", [0.1, 0.5, 1.0])
def test_principled_white_furnace(session, roughness):
    """White dielectric Principled (specular over diffuse, with and without a coat): the
    specular layer takes from the diffuse what it reflects, so the albedo stays near 1
    (Cycles' layering loses up to ~3% at roughness 1: the layer's albedo estimate counts its
    multiple scattering as lossless, the lobe does not); a white
    F82 metal keeps all of it (multiscatter GGX)."""
    for angle in (0, 45, 75):
        for kw, low in ((dict(base=(1, 1, 1), roughness=roughness), 0.96),
                        (dict(base=(1, 1, 1), roughness=roughness, coat=1.0, coat_roughness=0.2), 0.95),
                        (dict(base=(1, 1, 1), metallic=1.0, roughness=roughness), 0.98)):
            a = principled_albedo(session, angle, **kw)
            assert low <= a <= 1.02, f"albedo {a:.4f} at {angle} deg, {kw}"
    # without the layering (diffuse weight 1 under the specular) the albedo would exceed 1:
    plain = principled_albedo(session, 60, base=(1, 1, 1), roughness=roughness, specular=0.0)
    np.testing.assert_allclose(plain, 1.0, atol=0.01)


# ---- lights: one kind per scene -----------------------------------------------------------

P0 = np.zeros(3)  # shading point of the single-light scenes


@pytest.mark.parametrize("theta,phi", [(IC_THETA, IC_PHI), (IC_THETA_CONSISTENT, IC_PHI_CONSISTENT)])
def test_ic_stratified_hemisphere(session, theta, phi):
    """The irradiance cache's hemisphere (ic_hemisphere.rgen, thesis eq. 3.20), with the thesis'
    strata and consistent mode's: sample i lies in stratum s = i mod theta phi (theta index
    j = s // phi, phi index k = s % phi, with sin^2(theta) in [j, j+1) / theta and phi in
    2 pi [k, k+1) / phi), and together the samples follow cos(theta) / pi."""
    n = N // (theta * phi) * (theta * phi)
    r = session.test_sampling(TEST_IC_HEMISPHERE, [float(theta), float(phi), 0.0, 0.0, 0.0], n, seed=SEED + 900)
    d = r[:, 0, :3].astype(np.float64)
    np.testing.assert_allclose(r[:, 0, 3], np.maximum(d[:, 2], 0.0) / math.pi, rtol=1e-5, atol=1e-7)
    stratum = np.arange(n) % (theta * phi)
    j, k = stratum // phi, stratum % phi
    sin2 = 1.0 - d[:, 2] ** 2
    assert np.all(sin2 >= j / theta - 1e-5) and np.all(sin2 <= (j + 1) / theta + 1e-5)
    azimuth = np.mod(np.arctan2(d[:, 1], d[:, 0]), 2 * math.pi) / (2 * math.pi) * phi
    assert np.all((azimuth >= k - 1e-3) & (azimuth <= k + 1 + 1e-3) | (k == phi - 1) & (azimuth < 1e-3))
    check_fit(f"ic stratified cosine hemisphere {theta}x{phi}", SphereGrid.sphere(16, 32), d, n,
              lambda dirs: np.maximum(np.asarray(dirs)[:, 2], 0.0) / math.pi)


def emission_mesh(corners, material):
    idx = [[0, 1, 2]] if len(corners) == 3 else [[0, 1, 2], [0, 2, 3]]
    return Mesh(np.asarray(corners, np.float64), np.asarray(idx), material_indices=np.full(len(idx), material))


@pytest.fixture
def power_cdf():
    """Lights picked by the power CDF alone (no light tree) for scenes updated in the test."""
    before = pc._native.light_tree_min_lights()
    pc._native.set_light_tree_min_lights(2**32 - 1)
    yield
    pc._native.set_light_tree_min_lights(before)


@pytest.fixture
def light_tree():
    """Lights picked through the light tree, however few, for scenes updated in the test."""
    before = pc._native.light_tree_min_lights()
    pc._native.set_light_tree_min_lights(0)
    yield
    pc._native.set_light_tree_min_lights(before)


def test_triangle_lights(session, power_cdf):
    """An emissive quad and an emissive triangle of other area and emission: selection by
    power (2 pi L A, two-sided), radiance, chi-square (close by: spherical triangles); seen
    from far away (below TRI_SPHERICAL_MIN), uniform area sampling."""
    quad = np.array([[-0.6, 0.3, 1.5], [0.2, 0.3, 1.7], [0.2, 0.8, 1.7], [-0.6, 0.8, 1.5]])
    tri = np.array([[0.3, -0.9, 1.2], [0.9, -0.6, 1.0], [0.4, -0.2, 1.4]])
    em_q, em_t = 5.0, 2.0
    scene = lights_scene(
        meshes=[emission_mesh(quad, 0), emission_mesh(tri, 1)],
        materials=[Material("emission", emission=(em_q,) * 3), Material("emission", emission=(em_t,) * 3)])
    r = sample_lights(session, scene, P0, seed=SEED + 1)
    ok = r[:, 1, 2] > 0.5
    assert ok.all() and not (r[:, 1, 3] > 0.5).any()
    q = P0 + r[:, 0, :3].astype(np.float64) * r[:, 1, 1:2].astype(np.float64)
    on_quad = np.isclose(r[:, 1, 0], em_q, rtol=1e-6)
    assert np.all(on_quad | np.isclose(r[:, 1, 0], em_t, rtol=1e-6))
    area_q = np.linalg.norm(np.cross(quad[1] - quad[0], quad[3] - quad[0]))
    area_t = 0.5 * np.linalg.norm(np.cross(tri[1] - tri[0], tri[2] - tri[0]))
    check_multinomial("triangles: selection by power", [on_quad.sum(), (~on_quad).sum()],
                      [em_q * area_q, em_t * area_t])
    # points lie on their emitter
    eu, ev = quad[1] - quad[0], quad[3] - quad[0]
    n_q = unit(np.cross(eu, ev))
    assert np.abs((q[on_quad] - quad[0]) @ n_q).max() < 1e-4
    n_t = unit(np.cross(tri[1] - tri[0], tri[2] - tri[0]))
    assert np.abs((q[~on_quad] - tri[0]) @ n_t).max() < 1e-4
    grid = SphereGrid.bounding(P0, np.concatenate([quad, tri]))
    check_light_hits(session, P0, r)
    check_fit("triangle lights", grid, r[ok, 0, :3], N, light_pdf(session, P0))
    # far away: uniform over the quad (both of its triangles), by area
    far = np.array([0.0, 0.0, -40.0])
    r = session.test_sampling(TEST_LIGHT, [*far, 0.0, 0.0], 100_000, seed=SEED + 30)
    check_light_hits(session, far, r)
    on_quad = np.isclose(r[:, 1, 0], em_q, rtol=1e-6)
    q = far + r[on_quad, 0, :3].astype(np.float64) * r[on_quad, 1, 1:2].astype(np.float64)
    uv = np.linalg.lstsq(np.stack([eu, ev], 1), (q - quad[0]).T, rcond=None)[0].T
    back = quad[0] + uv @ np.stack([eu, ev])
    assert np.abs(back - q).max() < 2e-3
    assert uv.min() > -1e-3 and uv.max() < 1 + 1e-3
    hist = np.histogram2d(uv[:, 0], uv[:, 1], bins=8, range=[[0, 1], [0, 1]])[0]
    check_multinomial("triangles: uniform over the quad from afar", hist.ravel(), np.ones(64))


# ---- spherical triangles (Arvo 1995) --------------------------------------------------------

TRI_SPHERICAL_MIN, TRI_SPHERICAL_MAX = 1e-3, 6.2  # shaders/lib/lights.glsl


def solid_angle(p, a, b, c):
    """Van Oosterom & Strackee 1983, in float64."""
    a, b, c = (unit(np.asarray(x, np.float64) - p) for x in (a, b, c))
    return 2.0 * math.atan2(abs(a @ np.cross(b, c)), 1.0 + a @ b + b @ c + c @ a)


def sub_triangles(t, k=4):
    """The k^2 triangles of t's k-fold midpoint subdivision, and a function giving the one
    each barycentric (b1, b2) falls in."""
    pt = lambda i, j: t[0] + (i / k) * (t[1] - t[0]) + (j / k) * (t[2] - t[0])
    tris = [(pt(i, j), pt(i + 1, j), pt(i, j + 1)) for i in range(k) for j in range(k - i)]
    tris += [(pt(i + 1, j), pt(i + 1, j + 1), pt(i, j + 1)) for i in range(k - 1) for j in range(k - 1 - i)]
    index = {}
    for n, (i, j) in enumerate([(i, j) for i in range(k) for j in range(k - i)]):
        index[(i, j, 0)] = n
    for n, (i, j) in enumerate([(i, j) for i in range(k - 1) for j in range(k - 1 - i)]):
        index[(i, j, 1)] = k * (k + 1) // 2 + n

    def which(b1, b2):
        x, y = np.clip(b1 * k, 0, k - 1e-9), np.clip(b2 * k, 0, k - 1e-9)
        i, j = np.floor(x).astype(int), np.floor(y).astype(int)
        up = ((x - i) + (y - j) > 1.0).astype(int)
        j = np.minimum(j, k - 1 - i)  # rounding at the hypotenuse
        up = np.where(i + j == k - 1, 0, up)
        return np.array([index[(a, b, u)] for a, b, u in zip(i, j, up)])
    return tris, which


# name: (triangle, chi-square over a cap as well). Solid angles from the origin in comments.
SPHERICAL_CASES = {
    "large close": ([[-1.0, -1.0, 0.5], [1.5, -0.5, 0.6], [0.0, 1.2, 0.4]], True),      # 3.2 sr
    "nearly a hemisphere": ([[-30.0, -30.0, 0.4], [30.0, -30.0, 0.4], [0.0, 40.0, 0.4]], False),  # 6.1 sr
    "filling the hemisphere": ([[-30.0, -30.0, 0.05], [30.0, -30.0, 0.05], [0.0, 40.0, 0.05]], False),  # area
    "sliver": ([[0.2, -1.0, 0.5], [0.2, 1.0, 0.5], [0.203, 0.0, 0.52]], False),          # thin needle
    "grazing": ([[1.0, -0.5, 0.02], [3.0, -0.4, 0.03], [2.0, 0.6, 0.025]], False),       # p near its plane
    "just above the threshold": ([[0.0, 0.0, 3.0], [0.17, 0.0, 3.0], [0.0, 0.14, 3.0]], False),
    "just below the threshold": ([[0.0, 0.0, 3.0], [0.1, 0.0, 3.0], [0.0, 0.08, 3.0]], False),
}


@pytest.mark.parametrize("case", list(SPHERICAL_CASES))
def test_spherical_triangle(session, case):
    """One emissive triangle close to p: directions uniform over its solid angle (16
    sub-triangles get samples in proportion to their solid angles), on the triangle, with
    the pdf 1/omega in float64 -- or by area below TRI_SPHERICAL_MIN / above TRI_SPHERICAL_MAX,
    16 sub-triangles in proportion to their areas; the pdf MIS evaluates for a BSDF ray
    along each sample (triangle_light_pdf) equals the sampler's."""
    corners, chi2_cap = SPHERICAL_CASES[case]
    t = np.asarray(corners, np.float64)
    omega = solid_angle(P0, *t)
    spherical = TRI_SPHERICAL_MIN <= omega <= TRI_SPHERICAL_MAX
    assert spherical == (case not in ("filling the hemisphere", "just below the threshold")), omega
    scene = lights_scene(meshes=[emission_mesh(t, 0)], materials=[Material("emission", emission=(3.0,) * 3)])
    n = 100_000
    r = sample_lights(session, scene, P0, n=n, seed=SEED + 40 + list(SPHERICAL_CASES).index(case))
    ok = r[:, 1, 2] > 0.5
    assert ok.mean() > 0.9999, f"{case}: {(~ok).sum()} samples rejected"
    wi, dist = r[ok, 0, :3].astype(np.float64), r[ok, 1, 1].astype(np.float64)
    q = P0 + wi * dist[:, None]
    e1, e2 = t[1] - t[0], t[2] - t[0]
    b = np.linalg.lstsq(np.stack([e1, e2], 1), (q - t[0]).T, rcond=None)[0]
    scale = np.linalg.norm(q - P0, axis=1).max()
    assert np.abs(t[0] + b.T @ np.stack([e1, e2]) - q).max() < 1e-4 * scale, f"{case}: points off the plane"
    tol = 2e-3 if case == "sliver" else 1e-4
    assert b.min() > -tol and b.sum(0).max() < 1 + tol, f"{case}: points outside the triangle"
    # the sampler's pdf: 1/omega or the area density
    cos_l = np.abs(wi @ unit(np.cross(e1, e2)))
    area = 0.5 * np.linalg.norm(np.cross(e1, e2))
    want = np.full(len(wi), 1.0 / omega) if spherical else dist ** 2 / (area * cos_l)
    assert_close_mostly(f"{case}: sampler pdf", r[ok, 0, 3], want, rtol=2e-3, loose=np.inf, fraction=1e-3)
    # the eval's Moller-Trumbore test misses points near a 1:600 sliver's long edges more often
    check_light_hits(session, P0, r, fraction=3e-3 if case == "sliver" else 1e-4)
    tris, which = sub_triangles(t)
    mass = [solid_angle(P0, *x) for x in tris] if spherical else [1.0] * len(tris)
    counts = np.bincount(which(b[0], b[1]), minlength=len(tris))
    check_multinomial(f"spherical triangle {case}: sub-triangles", counts, mass)
    if chi2_cap:
        check_fit(f"spherical triangle {case}", SphereGrid.bounding(P0, t), wi, n, light_pdf(session, P0))


def test_light_tree(session, light_tree):
    """Many lights of every local kind through the light tree: each picked with the
    probability light_pick_pdf evaluates when a BSDF ray hits it (the hit's pdf equals the
    sampler's), chi-square over the sphere, with and without a surface normal at p; and a
    light next to p is picked far more often than its share of the power."""
    rng = np.random.default_rng(7)
    # 27 Fibonacci directions around p, 0.68 rad apart: no two lights overlap as seen from p.
    fib = [np.array([math.sqrt(1 - z * z) * math.cos(2.39996 * k), math.sqrt(1 - z * z) * math.sin(2.39996 * k), z])
           for k, z in ((k, 1.0 - (k + 0.5) / 13.5) for k in range(27))]
    analytic, near_k = (4, 13, 22), 26
    meshes, materials = [], []
    for k in (k for k in range(27) if k not in analytic and k != near_k):  # 23 triangles facing p, 2-3 away
        c = fib[k] * rng.uniform(2.0, 3.0)
        a, b2 = frame_around(c)[:2]
        size = 0.5
        t = [c + size * a, c - 0.5 * size * a + 0.8 * size * b2, c - 0.5 * size * a - 0.8 * size * b2]
        meshes.append(emission_mesh(t, len(materials)))
        materials.append(Material("emission", emission=(float(rng.uniform(1.0, 6.0)),) * 3))
    c = 0.2 * fib[near_k]  # a small triangle 0.2 from p
    a, b2 = frame_around(c)[:2]
    meshes.append(emission_mesh([c + 0.06 * a, c - 0.03 * a + 0.05 * b2, c - 0.03 * a - 0.05 * b2], len(materials)))
    materials.append(Material("emission", emission=(1.0,) * 3))
    lights = [Light("area", power=40.0, position=tuple(3.0 * fib[4]), direction=tuple(-fib[4]), size=0.6),
              Light("point", power=60.0, position=tuple(3.5 * fib[13]), radius=0.2),
              Light("spot", power=80.0, position=tuple(3.5 * fib[22]), direction=tuple(-fib[22]),
                    radius=0.15, spot_size=math.radians(40), spot_blend=0.3)]
    scene = lights_scene(lights, meshes, materials)
    for normal in (False, True):  # without and with the receiver term (normal +z)
        r = sample_lights(session, scene, P0, seed=SEED + 50 + 2 * normal, normal=normal)
        ok = r[:, 1, 2] > 0.5
        assert ok.mean() > 0.999
        check_light_hits(session, P0, r, normal=normal)
        check_fit(f"light tree{' with a normal' if normal else ''}", SphereGrid.sphere(), r[ok, 0, :3], N,
                  light_pdf(session, P0, normal))
    # The near triangle holds < 0.1 % of the power; seen from 0.2 away the tree picks it often.
    picked = (r[ok, 1, 1] < 0.5).mean()
    pc._native.set_light_tree_min_lights(2**32 - 1)  # the power CDF (the fixture restores)
    r = sample_lights(session, scene, P0, n=100_000, seed=SEED + 51)
    picked_cdf = (r[:, 1, 1] < 0.5).mean()
    assert picked_cdf < 1e-3 and picked > 0.01, (
        f"the light next to p: picked for {picked:.4f} of the samples by the tree, {picked_cdf:.5f} by power")


def test_light_tree_cuts_only_lights_that_cannot_reach_p(session, light_tree):
    """The tree's importance is zero for a light that cannot light p (so it is never sampled)
    and never for one that can: one-sided rectangles facing p,
    facing away, and nearly edge-on; Soft Falloff spots with p inside their cone, far
    outside it, and just outside the cone of the disk's centre but inside that of its near
    edge (lit by part of the disk: the bounding sphere's angle theta_u must be subtracted)."""
    rng = np.random.default_rng(11)
    fib = [np.array([math.sqrt(1 - z * z) * math.cos(2.39996 * k), math.sqrt(1 - z * z) * math.sin(2.39996 * k), z])
           for k, z in ((k, 1.0 - (k + 0.5) / 20.0) for k in range(40))]
    lights, targets, edge = [], [], []  # targets: (centre, spanning vectors) of each light's emitting area
    for k, f in enumerate(fib):
        c = f * rng.uniform(1.5, 2.5)
        to_p = -f
        side = frame_around(to_p)[0]
        if k % 4 < 3:  # rectangles: facing p, facing away (>= 120 deg), nearly edge-on (84-88 deg)
            angle = math.radians((rng.uniform(0, 50), rng.uniform(120, 180), rng.uniform(84, 88))[k % 4])
            normal = math.cos(angle) * to_p + math.sin(angle) * side
            lights.append(Light("area", power=10.0, position=tuple(c), direction=tuple(normal), size=0.3))
            u, v = frame_around(normal)[:2]
            targets.append((c, 0.1 * u, 0.1 * v))  # within the square whichever its rotation
        else:  # spots, cone half-angle 20 deg, radius 0.4 (9-15 deg seen from p)
            kind = k // 4 % 3  # p inside the cone, far outside, just outside (lit by the disk's near part)
            off = math.radians((rng.uniform(0, 10), 60.0, 27.0)[kind])
            axis = math.cos(off) * to_p + math.sin(off) * side
            lights.append(Light("spot", power=30.0, position=tuple(c), direction=tuple(axis), radius=0.4,
                                spot_size=math.radians(40), spot_blend=0.0, soft_falloff=True))
            u, v = frame_around(to_p)[:2]  # the disk faces p
            targets.append((c, 0.4 * u, 0.4 * v))
            if kind == 2:
                edge.append(len(lights) - 1)
    for normal in (False, True):
        # Without the edge spots (most of their disk misses p's cone), a sample fails only when the
        # walk enters a node whose lights all face away, which its merged cone cannot tell: 9.9%
        # (16% with the cut-off replaced by a floor of 0.05 on the cosine bound).
        r = sample_lights(session, lights_scene([l for i, l in enumerate(lights) if i not in edge]), P0,
                          n=100_000, seed=SEED + 60 + normal, normal=normal)
        failed = 1.0 - (r[:, 1, 2] > 0.5).mean()
        assert failed < 0.12, f"{failed:.3f} of the light samples went to lights that cannot reach p"
        # Directions to points on every light: wherever light arrives, NEE can sample it.
        session.update(lights_scene(lights))
        dirs = []
        for c, a, b in targets:
            s, t = rng.uniform(-1, 1, (2, 200))
            dirs.append(c + s[:, None] * a + t[:, None] * b)
        d = np.concatenate(dirs)
        d /= np.linalg.norm(d, axis=1, keepdims=True)
        e = session.test_sampling(TEST_LIGHT + EVAL, [*P0, float(normal), 0.0], len(d), directions=d)
        lit = (e[:, 1, 0] > 0).reshape(len(lights), 200)
        unsampled = lit & ~(e[:, 1, 1] > 0).reshape(len(lights), 200)
        assert all(lit[i].any() for i in edge), "the edge spots do not light p"
        assert lit.sum() > 2000, lit.sum()
        assert not unsampled.any(), (f"{unsampled.sum()} directions bring light that the tree never samples "
                                     f"(lights {np.flatnonzero(unsampled.any(axis=1)).tolist()})")


def test_sphere_light(session):
    c, rad, power = np.array([0.4, -0.2, 2.0]), 0.3, 25.0
    scene = lights_scene([Light("point", power=power, position=tuple(c), radius=rad)])
    r = sample_lights(session, scene, P0, seed=SEED + 2)
    ok = r[:, 1, 2] > 0.5
    assert ok.all() and not (r[:, 1, 3] > 0.5).any()
    np.testing.assert_allclose(r[:, 1, 0], power / (4 * math.pi ** 2 * rad ** 2), rtol=1e-5)
    d = np.linalg.norm(c - P0)
    q = P0 + r[:, 0, :3].astype(np.float64) * r[:, 1, 1:2]
    np.testing.assert_allclose(np.linalg.norm(q - c, axis=1), rad, atol=2e-4)  # on the sphere,
    assert np.all(r[:, 1, 1] <= math.sqrt(d * d - rad * rad) + 1e-4)          # the near side
    cos_max = math.sqrt(1 - (rad / d) ** 2)
    check_light_hits(session, P0, r)
    check_fit("sphere light", SphereGrid.cone(c - P0, cos_max), r[:, 0, :3], N, light_pdf(session, P0))


@pytest.mark.parametrize("tilt_deg", [0.0, 40.0])
def test_sphere_light_irradiance(session, tilt_deg):
    """NEE irradiance of a sphere light: E = pi L sin^2(theta_max) cos(tilt) with
    L = P / (4 pi^2 r^2) (Cycles), i.e. P cos(tilt) / (4 pi d^2) -- the sphere is above the
    horizon of the tilted normal."""
    c, rad, power = np.array([0.0, 0.0, 1.5]), 0.4, 100.0
    scene = lights_scene([Light("point", power=power, position=tuple(c), radius=rad)])
    r = sample_lights(session, scene, P0, n=100_000, seed=SEED + 3)
    t = math.radians(tilt_deg)
    normal = np.array([math.sin(t), 0.0, math.cos(t)])
    cos = r[:, 0, :3].astype(np.float64) @ normal
    assert cos.min() > 0
    estimate = float(np.mean(r[:, 1, 0] * cos / r[:, 0, 3]))
    d = np.linalg.norm(c - P0)
    assert estimate == pytest.approx(power * math.cos(t) / (4 * math.pi * d * d), rel=0.01)


def test_soft_falloff_point_light(session):
    """Cycles' Soft Falloff: a disk of the light's radius centred on it and facing the shading
    point, with the sphere's radiance P / (4 pi^2 r^2), sampled uniformly by area. Its NEE
    irradiance on a surface facing it is pi L r^2 / (d^2 + r^2) = P / (4 pi (d^2 + r^2))."""
    c, rad, power = np.array([0.3, -0.2, 0.9]), 0.5, 25.0
    scene = lights_scene([Light("point", power=power, position=tuple(c), radius=rad, soft_falloff=True)])
    r = sample_lights(session, scene, P0, seed=SEED + 20)
    ok = r[:, 1, 2] > 0.5
    assert ok.all() and not (r[:, 1, 3] > 0.5).any()
    np.testing.assert_allclose(r[:, 1, 0], power / (4 * math.pi ** 2 * rad ** 2), rtol=1e-5)
    axis = unit(c - P0)
    q = P0 + r[:, 0, :3].astype(np.float64) * r[:, 1, 1:2]
    assert np.abs((q - c) @ axis).max() < 1e-4                      # in the plane facing P0,
    assert np.linalg.norm(q - c, axis=1).max() <= rad * (1 + 1e-4)  # within the radius
    assert np.linalg.norm(q - c, axis=1).min() < 0.05 * rad          # filling it
    d = np.linalg.norm(c - P0)
    cos_max = d / math.hypot(d, rad)
    check_light_hits(session, P0, r)
    check_fit("soft falloff point light", SphereGrid.cone(c - P0, cos_max), r[:, 0, :3], N, light_pdf(session, P0))
    cos = r[:, 0, :3].astype(np.float64) @ axis
    estimate = float(np.mean(r[:, 1, 0] * cos / r[:, 0, 3]))
    assert estimate == pytest.approx(power / (4 * math.pi * (d * d + rad * rad)), rel=0.01)


def test_soft_falloff_spot_light(session):
    """The spot cone of a Soft Falloff spot is evaluated along each sampled direction (Cycles'
    spot_light_sample with is_sphere off); hits see the same value."""
    pos, rad, power = np.array([0.0, 0.0, 0.8]), 0.4, 50.0
    t = math.radians(25.0)
    direction = np.array([math.sin(t), 0.0, -math.cos(t)])
    light = Light("spot", power=power, position=tuple(pos), direction=tuple(direction), radius=rad,
                  spot_size=math.radians(60.0), spot_blend=0.5, soft_falloff=True)
    r = sample_lights(session, lights_scene([light]), P0, seed=SEED + 21)
    ok = r[:, 1, 2] > 0.5
    assert 0.2 < ok.mean() < 1.0  # the cone's edge crosses the disk: some samples are dark
    wi = r[ok, 0, :3].astype(np.float64)
    cos_half = math.cos(math.radians(30.0))
    att = np.array([smoothstep((-w @ direction - cos_half) / ((1 - cos_half) * 0.5)) for w in wi])
    peak = power / (4 * math.pi ** 2 * rad ** 2)
    np.testing.assert_allclose(r[ok, 1, 0], att * peak, rtol=2e-3, atol=1e-5 * peak)
    # BSDF rays along the samples: the same pdf, and radiance (absolute tolerance: where the
    # smoothstep is ~0 float rounding of the direction changes it relatively a lot)
    e = session.test_sampling(TEST_LIGHT + EVAL, [*P0, 0.0, 0.0], int(ok.sum()), directions=r[ok, 0, :3])
    assert_close_mostly("soft spot hit pdf", e[:, 1, 1], r[ok, 0, 3], loose=np.inf)
    np.testing.assert_allclose(e[:, 1, 0], r[ok, 1, 0], rtol=1e-3, atol=1e-5 * peak)
    d = np.linalg.norm(pos - P0)
    check_fit("soft falloff spot light", SphereGrid.cone(pos - P0, d / math.hypot(d, rad)), wi, N,
              light_pdf(session, P0))


def spot_scene(power=50.0, off_axis_deg=27.0):
    pos = np.array([0.0, 0.0, 2.0])
    t = math.radians(off_axis_deg)  # angle between the spot axis and the direction to P0
    direction = (math.sin(t), 0.0, -math.cos(t))
    light = Light("spot", power=power, position=tuple(pos), direction=direction, radius=0.2,
                  spot_size=math.radians(60.0), spot_blend=0.3)
    return lights_scene([light]), pos, light


def test_spot_light(session):
    power = 50.0
    scene, pos, light = spot_scene(power, 27.0)
    r = sample_lights(session, scene, P0, seed=SEED + 4)
    ok = r[:, 1, 2] > 0.5
    assert ok.all() and not (r[:, 1, 3] > 0.5).any()
    # Cycles: smoothstep((cos - cos_half) / ((1 - cos_half) * blend)) on the sphere's radiance
    cos_half = math.cos(math.radians(30.0))
    att = smoothstep((math.cos(math.radians(27.0)) - cos_half) / ((1 - cos_half) * 0.3))
    assert 0.3 < att < 0.9  # the point is inside the blend region
    np.testing.assert_allclose(r[:, 1, 0], att * power / (4 * math.pi ** 2 * 0.2 ** 2), rtol=1e-4)
    d = np.linalg.norm(pos - P0)
    cos_max = math.sqrt(1 - (0.2 / d) ** 2)
    check_light_hits(session, P0, r)
    check_fit("spot light", SphereGrid.cone(pos - P0, cos_max), r[:, 0, :3], N, light_pdf(session, P0))
    # outside the cone: nothing to sample, zero pdf
    scene, _, _ = spot_scene(power, 35.0)
    r = sample_lights(session, scene, P0, n=2000, seed=SEED + 4)
    assert not (r[:, 1, 2] > 0.5).any()
    dirs = np.tile(unit(pos - P0), (16, 1))
    assert np.all(light_pdf(session, P0)(dirs) == 0.0)


def test_sun_light(session):
    strength, angle = 3.0, math.radians(10.0)
    to_sun = unit([0.3, -0.5, 0.8])
    scene = lights_scene([Light("sun", power=strength, direction=tuple(-to_sun), angle=angle)])
    r = sample_lights(session, scene, P0, seed=SEED + 5)
    ok = r[:, 1, 2] > 0.5
    assert ok.all() and not (r[:, 1, 3] > 0.5).any() and np.all(r[:, 1, 1] >= DISTANT)
    h = angle / 2
    np.testing.assert_allclose(r[:, 1, 0], strength / (math.pi * math.sin(h) ** 2), rtol=1e-4)
    # irradiance at normal incidence is the strength
    e = np.mean(r[:, 1, 0] * (r[:, 0, :3].astype(np.float64) @ to_sun) / r[:, 0, 3])
    assert e == pytest.approx(strength, rel=0.01)
    check_light_hits(session, P0, r)
    check_fit("sun (10 deg)", SphereGrid.cone(to_sun, math.cos(h)), r[:, 0, :3], N, light_pdf(session, P0))


@pytest.mark.parametrize("shape", ["rectangle", "ellipse"])
def test_area_light(session, shape):
    pos = np.array([0.3, 0.2, 1.6])
    normal = unit([0.2, 0.1, -1.0])  # emits downwards, towards P0
    u = unit(np.cross(normal, [0.3, 1.0, 0.0]))
    v = np.cross(normal, u)  # u x v = -normal (Blender: the light points along its -Z)
    size, size_y, power = 0.9, 0.5, 40.0
    light = Light("area", power=power, position=tuple(pos), direction=tuple(normal), shape=shape,
                  size=size, size_y=size_y, axis_u=tuple(u), axis_v=tuple(v))
    scene = lights_scene([light])
    r = sample_lights(session, scene, P0, seed=SEED + 6)
    ok = r[:, 1, 2] > 0.5
    assert ok.all() and not (r[:, 1, 3] > 0.5).any()
    area = size * size_y * (1.0 if shape == "rectangle" else math.pi / 4)
    np.testing.assert_allclose(r[:, 1, 0], power / (math.pi * area), rtol=1e-5)  # P / (pi A)
    q = P0 + r[:, 0, :3].astype(np.float64) * r[:, 1, 1:2]
    assert np.abs((q - pos) @ normal).max() < 1e-4
    su, sv = (q - pos) @ u / size, (q - pos) @ v / size_y  # in [-0.5, 0.5]
    if shape == "rectangle":
        assert np.abs(su).max() < 0.5 + 1e-4 and np.abs(sv).max() < 0.5 + 1e-4
        hist = np.histogram2d(su, sv, bins=8, range=[[-0.5, 0.5], [-0.5, 0.5]])[0]
        check_multinomial("rect: uniform by area", hist.ravel(), np.ones(64))
        outline = pos + np.array([[a * size, b * size_y] for a in (-.5, .5) for b in (-.5, .5)]) @ np.stack([u, v])
    else:
        rho2 = 4 * (su ** 2 + sv ** 2)
        assert rho2.max() < 1 + 1e-3
        hist = np.histogram2d(rho2, np.arctan2(sv, su), bins=8, range=[[0, 1], [-math.pi, math.pi]])[0]
        check_multinomial("disk: uniform by area", hist.ravel(), np.ones(64))
        a = np.linspace(0, 2 * math.pi, 64, endpoint=False)
        outline = pos + 0.5 * np.stack([size * np.cos(a), size_y * np.sin(a)], 1) @ np.stack([u, v])
    grid = SphereGrid.bounding(P0, outline)
    check_light_hits(session, P0, r)
    check_fit(f"area light ({shape})", grid, r[:, 0, :3], N, light_pdf(session, P0))
    # one-sided: nothing from behind
    behind = pos + 1.0 * normal * -1.0
    r = sample_lights(session, scene, behind, n=2000, seed=SEED + 6)
    assert not (r[:, 1, 2] > 0.5).any()
    assert np.all(light_pdf(session, behind)(np.tile(unit(pos - behind), (16, 1))) == 0.0)


def env_map(h=32, w=64):
    rows, cols = np.meshgrid(np.arange(h) + 0.5, np.arange(w) + 0.5, indexing="ij")
    u, v = cols / w, 1.0 - rows / h
    m = np.zeros((h, w, 3), np.float32)
    grad = 0.4 + 0.8 * v + 0.3 * np.cos(2 * math.pi * u)  # brighter towards the zenith
    m[..., 0], m[..., 1], m[..., 2] = grad, 0.7 * grad, 0.4 + 0.2 * u
    blob = 60.0 * np.exp(-(((u - 0.3) / 0.05) ** 2 + ((v - 0.65) / 0.07) ** 2))
    m += blob[..., None].astype(np.float32) * np.array([1.0, 0.8, 0.5], np.float32)
    m[20:24, 40:48] = 0.0  # a black patch: must never be sampled
    return m


def test_environment_map(session):
    m = env_map()
    h, w = m.shape[:2]
    scene = lights_scene(world=World(color=(1.0, 0.0, 1.0), map=m))
    r = sample_lights(session, scene, P0, seed=SEED + 7)
    ok = r[:, 1, 2] > 0.5
    assert ok.mean() > 0.9999 and not (r[:, 1, 3] > 0.5).any() and np.all(r[ok, 1, 1] >= DISTANT)
    dirs = r[ok, 0, :3].astype(np.float64)
    # radiance is the map texel under Blender's equirectangular mapping (away from texel edges)
    uu, vv = direction_to_equirectangular(dirs)
    fx, fy = uu * w, (1.0 - vv) * h
    inner = (np.abs(fx - np.round(fx)) > 1e-3) & (np.abs(fy - np.round(fy)) > 1e-3)
    col = np.clip(fx.astype(int), 0, w - 1)
    row = np.clip(fy.astype(int), 0, h - 1)
    np.testing.assert_allclose(r[ok, 1, 0][inner], m[row, col, 0][inner], rtol=1e-6)
    # pdf at texel centres ∝ luminance: lum * W * H / (2 pi^2 * sum(lum * sin(theta)))
    lum = m @ np.array([0.2126, 0.7152, 0.0722], np.float32)
    theta_c = math.pi * (np.arange(h) + 0.5) / h
    total = float((lum.astype(np.float64) * np.sin(theta_c)[:, None]).sum())
    rows_c, cols_c = np.meshgrid(np.arange(h) + 0.5, np.arange(w) + 0.5, indexing="ij")
    centres = equirectangular_to_direction(cols_c / w, 1.0 - rows_c / h).reshape(-1, 3)
    got = light_pdf(session, P0)(centres.astype(np.float32))
    want = lum.ravel() * w * h / (2 * math.pi ** 2 * total)
    np.testing.assert_allclose(got, want, rtol=5e-3, atol=1e-4 * want.mean())
    # NEE estimate of the integral of L over the sphere (red channel) with the sampler's pdf
    omega = (np.cos(math.pi * np.arange(h) / h) - np.cos(math.pi * np.arange(1, h + 1) / h)) * (2 * math.pi / w)
    exact = float((m[..., 0].astype(np.float64) * omega[:, None]).sum())
    estimate = float(np.mean(np.where(ok, r[:, 1, 0] / np.where(ok, r[:, 0, 3], 1.0), 0.0)))
    assert estimate == pytest.approx(exact, rel=0.01)
    # Bins not aligned with texels (3 texel rows / columns per 4 bins), so the distribution
    # within texels is tested too; texel edges fall on sub-cell edges (24 * 4 = 3 * 32,
    # 48 * 4 = 3 * 64), where the pdf's jumps cost the midpoint rule nothing.
    check_light_hits(session, P0, r)
    check_fit("environment map", SphereGrid.sphere(24, 48), dirs, N, light_pdf(session, P0), nsub=4)


def test_constant_world(session):
    colour = (0.3, 0.5, 0.2)
    r = sample_lights(session, lights_scene(world=World(color=colour)), P0, seed=SEED + 8)
    ok = r[:, 1, 2] > 0.5
    assert ok.all() and not (r[:, 1, 3] > 0.5).any()
    np.testing.assert_allclose(r[:, 1, 0], colour[0], rtol=1e-6)
    np.testing.assert_allclose(r[:, 0, 3], 1.0 / (4 * math.pi), rtol=1e-5)
    check_light_hits(session, P0, r)
    check_fit("constant world", SphereGrid.sphere(16, 32), r[:, 0, :3], N, light_pdf(session, P0), nsub=4)


# ---- delta lights -------------------------------------------------------------------------

def test_point_light_delta(session, power_cdf):
    """Point light next to a rect light: delta samples along the axis with radiance
    P / (4 pi d^2), pdf = selection probability = P_point / (P_point + P_rect) (both W)."""
    pos, p_point, p_rect = np.array([0.5, -0.4, 1.8]), 30.0, 10.0
    rect = Light("area", power=p_rect, position=(-1.0, 0.0, 1.0), direction=(0.5, 0.0, -1.0), size=0.5)
    scene = lights_scene([Light("point", power=p_point, position=tuple(pos)), rect])
    r = sample_lights(session, scene, P0, n=20_000, seed=SEED + 9)
    delta = r[:, 1, 3] > 0.5
    assert (r[:, 1, 2] > 0.5).all()
    sel = p_point / (p_point + p_rect)
    check_multinomial("point vs rect: selection by power", [delta.sum(), (~delta).sum()], [sel, 1 - sel])
    d = np.linalg.norm(pos - P0)
    np.testing.assert_allclose(r[delta, 0, :3], np.tile(unit(pos - P0), (delta.sum(), 1)), atol=1e-6)
    np.testing.assert_allclose(r[delta, 1, 0], p_point / (4 * math.pi * d * d), rtol=1e-5)
    np.testing.assert_allclose(r[delta, 1, 1], d, rtol=1e-5)
    np.testing.assert_allclose(r[delta, 0, 3], sel, rtol=1e-5)
    # the rect's samples carry its own selection probability
    rect_pdf = light_pdf(session, P0)(r[~delta, 0, :3])
    np.testing.assert_allclose(r[~delta, 0, 3], rect_pdf, rtol=1e-3)


def test_sun_and_spot_delta(session):
    """Sun of angle 0 and a spot of radius 0: delta, right direction, radiance S and
    att * P / (4 pi d^2); each sample's pdf is its light's selection probability."""
    to_sun, strength = unit([-0.4, 0.2, 0.9]), 2.0
    pos, power = np.array([0.0, 0.0, 2.0]), 40.0
    spot = Light("spot", power=power, position=tuple(pos), direction=(math.sin(0.1), 0.0, -math.cos(0.1)),
                 spot_size=math.radians(60.0), spot_blend=0.3)
    floor = emission_mesh([[-1, -1, 0], [1, -1, 0], [1, 1, 0], [-1, 1, 0]], 0)  # gives the scene a size
    scene = lights_scene([Light("sun", power=strength, direction=tuple(-to_sun), angle=0.0), spot],
                         meshes=[floor], materials=[Material("diffuse")])
    r = sample_lights(session, scene, P0, n=20_000, seed=SEED + 10)
    assert (r[:, 1, 2] > 0.5).all() and (r[:, 1, 3] > 0.5).all()
    sun = r[:, 1, 1] >= DISTANT
    assert 0 < sun.sum() < len(r)
    np.testing.assert_allclose(r[sun, 0, :3], np.tile(to_sun, (sun.sum(), 1)), atol=1e-6)
    np.testing.assert_allclose(r[sun, 1, 0], strength, rtol=1e-6)
    np.testing.assert_allclose(r[~sun, 0, :3], np.tile(unit(pos), ((~sun).sum(), 1)), atol=1e-6)
    np.testing.assert_allclose(r[~sun, 1, 0], power / (4 * math.pi * 4.0), rtol=1e-5)  # att = 1 at 0.1 rad
    p_sun, p_spot = float(r[sun, 0, 3][0]), float(r[~sun, 0, 3][0])
    assert np.all(r[sun, 0, 3] == p_sun) and np.all(r[~sun, 0, 3] == p_spot)
    assert p_sun + p_spot == pytest.approx(1.0, rel=1e-6)
    check_multinomial("sun vs spot (delta): fraction == pdf", [sun.sum(), (~sun).sum()], [p_sun, p_spot])
    # delta lights have no density for a BSDF-sampled direction
    assert np.all(light_pdf(session, P0)(np.stack([to_sun, unit(pos)]).astype(np.float32)) == 0.0)


# ---- several lights together --------------------------------------------------------------

def test_mixed_lights(session, power_cdf):
    """Triangles, sphere, spot, rect, sun, a point light and a constant world in one scene:
    chi-square of the non-delta samples against the summed pdf, and selection by power among
    the lights whose power is defined in Watts (triangles, sphere, rect, point)."""
    quad = np.array([[-0.3, -0.3, 2.0], [0.3, -0.3, 2.0], [0.3, 0.3, 2.0], [-0.3, 0.3, 2.0]])
    em = 3.0
    sph_c, sph_r, sph_p = np.array([1.5, 0.0, 1.0]), 0.3, 40.0
    spot_c, spot_r, spot_p = np.array([0.0, -1.5, 1.2]), 0.2, 50.0
    rect_c, rect_p, rect_size = np.array([-1.5, 0.5, 0.8]), 30.0, (0.7, 0.4)
    point_c, point_p = np.array([0.5, 1.5, 1.5]), 20.0
    to_sun = unit([0.5, -0.8, 0.6])
    rect_n = unit(P0 - rect_c)
    lights = [
        Light("point", power=sph_p, position=tuple(sph_c), radius=sph_r),
        Light("spot", power=spot_p, position=tuple(spot_c), radius=spot_r, direction=tuple(unit(P0 - spot_c)),
              spot_size=math.radians(60.0), spot_blend=0.3),
        Light("area", power=rect_p, position=tuple(rect_c), direction=tuple(rect_n), shape="rectangle",
              size=rect_size[0], size_y=rect_size[1]),
        Light("point", power=point_p, position=tuple(point_c)),
        Light("sun", power=2.0, direction=tuple(-to_sun), angle=math.radians(10.0)),
    ]
    scene = lights_scene(lights, meshes=[emission_mesh(quad, 0)],
                         materials=[Material("emission", emission=(em,) * 3)], world=World(color=(0.1, 0.1, 0.1)))
    r = sample_lights(session, scene, P0, seed=SEED + 12)
    ok = r[:, 1, 2] > 0.5
    assert ok.all()
    delta = r[:, 1, 3] > 0.5
    dist = r[:, 1, 1].astype(np.float64)
    distant = dist >= DISTANT
    q = P0 + r[:, 0, :3].astype(np.float64) * np.where(distant, 0.0, dist)[:, None]
    on_sphere = ~delta & ~distant & (np.abs(np.linalg.norm(q - sph_c, axis=1) - sph_r) < 1e-3)
    on_spot = ~delta & ~distant & (np.abs(np.linalg.norm(q - spot_c, axis=1) - spot_r) < 1e-3)
    on_rect = ~delta & ~distant & (np.abs((q - rect_c) @ rect_n) < 1e-4)
    on_quad = ~delta & ~distant & (np.abs(q[:, 2] - 2.0) < 1e-4)
    groups = [on_quad, on_sphere, on_rect, delta]
    assert np.all(np.sum([on_quad, on_sphere, on_spot, on_rect, delta, distant], axis=0) == 1)
    area_q = 0.36
    check_multinomial("mixed: selection by power (W)", [g.sum() for g in groups],
                      [2 * math.pi * em * area_q, sph_p, rect_p, point_p])
    # the delta point light's pdf is its selection probability = its share of the samples
    assert float(r[delta, 0, 3][0]) == pytest.approx(delta.mean(), abs=4 * math.sqrt(delta.mean() / N))
    check_fit("mixed lights (non-delta)", SphereGrid.sphere(16, 32), r[~delta, 0, :3], N,
              light_pdf(session, P0))


# ---- ADRRS' weight window and expected-value split (shaders/techniques/adrrs.glsl) -------

TEST_ADRRS = 8


@pytest.mark.parametrize("ratio", [0.01, 0.2, 0.5, 1.0, 2.0, 3.7, 12.25, 40.0])
def test_adrrs_copies_have_mean_q_and_unit_weight(session, ratio):
    """r = v/C against the window [2/(1+s), 2s/(1+s)] (s = 5): below it the path survives with
    q = max(r/delta-, 0.1), above it splits into floor(q) or floor(q)+1 copies with mean
    q = r/delta+; inside, q = 1. The counts follow the two-point law (chi^2 over the two
    outcomes) and copies/q has mean 1: the estimator stays unbiased."""
    s, rr_min, n = 5.0, 0.1, 200_000
    lower, upper = 2.0 / (1.0 + s), 2.0 * s / (1.0 + s)
    expected_q = max(ratio / lower, rr_min) if ratio < lower else ratio / upper if ratio > upper else 1.0
    r = session.test_sampling(TEST_ADRRS, [ratio, s, rr_min, 1.0, 0.0], n, seed=7)
    q, copies, weight = r[:, 0, 0], r[:, 0, 1], r[:, 0, 2]
    assert np.allclose(q, expected_q, rtol=1e-5)
    low = math.floor(expected_q) if expected_q >= 1.0 else 0.0
    p_high = expected_q - low if expected_q >= 1.0 else expected_q  # P(low + 1 copies)
    assert set(np.unique(copies)) <= {low, low + 1.0}
    if 0.0 < p_high < 1.0:
        observed = np.array([(copies == low).sum(), (copies == low + 1).sum()], np.float64)
        expected = n * np.array([1.0 - p_high, p_high])
        assert chi2_sf(float(((observed - expected) ** 2 / expected).sum()), 1) > 1e-4
    assert abs(weight.mean() - 1.0) < 5.0 * weight.std() / math.sqrt(n) + 1e-6


def test_adrrs_without_splitting_leaves_heavy_paths_alone(session):
    r = session.test_sampling(TEST_ADRRS, [10.0, 5.0, 0.1, 0.0, 0.0], 1000, seed=1)
    assert np.all(r[:, 0, 0] == 1.0) and np.all(r[:, 0, 1] == 1.0)


# ---- the pixel filter (render/pixel_filter.h, camera.glsl's pixel_filter_sample) ----------

def filter_profile(kind, width, x):
    """Cycles' filter profiles (film.cpp): box over w, Gaussian over 3w, Blackman-Harris over 2w."""
    if kind == "GAUSSIAN":
        return np.exp(-2.0 * (6.0 * x / (3.0 * width)) ** 2), 1.5 * width
    if kind == "BLACKMAN_HARRIS":
        t = 2.0 * np.pi * (x / (2.0 * width) + 0.5)
        return 0.35875 - 0.48829 * np.cos(t) + 0.14128 * np.cos(2 * t) - 0.01168 * np.cos(3 * t), width
    return np.ones_like(x), 0.5 * width


def filter_cdf(kind, width, t):
    """P(offset <= t) for a camera sample's offset from its pixel centre."""
    _, half = filter_profile(kind, width, np.zeros(1))
    x = np.linspace(-half, half, 200_001)
    f, _ = filter_profile(kind, width, x)
    cdf = np.concatenate([[0.0], np.cumsum(0.5 * (f[1:] + f[:-1]))])
    return np.interp(t, x, cdf / cdf[-1], left=0.0, right=1.0)


@pytest.mark.parametrize("kind,width", [("BOX", 1.0), ("GAUSSIAN", 1.5), ("BLACKMAN_HARRIS", 1.5),
                                        ("BLACKMAN_HARRIS", 3.0)])
def test_pixel_filter_chi2(kind, width):
    # An orthographic camera, one world unit per pixel, over a black world and an emissive strip
    # 0.25 px wide off any pixel centre: each column's camera samples hit the strip with the
    # probability that the filter's offset lands on it, so the columns' hit counts histogram the
    # filter (every sample weighs 1: it is importance-sampled).
    from parallax_core.scene import Camera

    columns, rows, spp, frames = 24, 8, 256, 4
    x0, strip = 0.3, 0.25
    to_world = np.eye(4)[:3].copy()
    to_world[2, 3] = 1.0
    camera = Camera(camera_to_world=to_world, type="orthographic", window=(-12.0, 12.0, -4.0, 4.0))
    line = scenes.quad([(x0 - strip / 2, -10.0, 0.0), (x0 + strip / 2, -10.0, 0.0), (x0 + strip / 2, 10.0, 0.0),
                        (x0 - strip / 2, 10.0, 0.0)])
    white = Material("emission", (1.0, 1.0, 1.0), emission=(1.0, 1.0, 1.0), emission_strength=1.0)
    scene = SceneData([line], [], [white], [], [], World((0.0, 0.0, 0.0), 1.0), camera, columns, rows)
    s = pc.Session(columns, rows)
    s.set_params(method="pt", max_depth=0, samples_per_frame=spp, use_adaptive_sampling=False, seed=SEED,
                 pixel_filter_type=kind, filter_width=width)
    s.update(scene)
    s.render(frames)
    n = spp * frames * rows  # samples per column
    hits = np.rint(s.read("combined")[..., 0] * spp * frames).sum(axis=0)
    centres = np.arange(columns) - 12.0 + 0.5
    p = filter_cdf(kind, width, x0 + strip / 2 - centres) - filter_cdf(kind, width, x0 - strip / 2 - centres)
    assert hits[p == 0.0].sum() == 0, "samples beyond the filter's support"
    # Independent binomial columns: Pearson's statistic over the columns expected to see >= 5 hits.
    tested = n * np.minimum(p, 1.0 - p) >= 5.0
    stat = float(((hits[tested] - n * p[tested]) ** 2 / (n * p[tested] * (1.0 - p[tested]))).sum())
    assert tested.sum() >= 1
    assert chi2_sf(stat, int(tested.sum())) > ALPHA, (kind, width, hits[tested], n * p[tested])


@pytest.mark.parametrize("kind,width,tolerance", [("BLACKMAN_HARRIS", 1.5, 0.002), ("BLACKMAN_HARRIS", 3.0, 0.002),
                                                  ("GAUSSIAN", 1.5, 0.012)])
def test_pixel_filter_table_is_as_wide_as_its_filter(kind, width, tolerance):
    # The image's blur is the offsets' spread: the table's (its entries interpolated, as
    # camera.glsl reads them, at a fine grid of u) against the filter's own standard deviation.
    # A 256-entry table was 0.8% (Blackman-Harris 1.5 px) and 4.2% (Gaussian) too wide: it
    # fills each tail cell evenly. Cycles' table (1024 entries) is 0.2% wide for Blackman-Harris.
    table = np.asarray(pc.pixel_filter_table(kind, width), np.float64)
    u = (np.arange(400_000) + 0.5) / 400_000
    offsets = np.interp(u * (table.size - 1), np.arange(table.size), table)
    _, half = filter_profile(kind, width, np.zeros(1))
    x = np.linspace(-half, half, 400_001)
    f, _ = filter_profile(kind, width, x)
    exact = np.sqrt((f * x * x).sum() / f.sum())
    assert abs(offsets.mean()) < 1e-4
    assert abs(offsets.std() / exact - 1.0) < tolerance, offsets.std() / exact
    with pytest.raises(ValueError, match="CATMULL"):
        pc.pixel_filter_table("CATMULL", 1.0)


# ---- the camera's aperture (shaders/lib/sampling.glsl, aperture_sample) -------------------

TEST_APERTURE = 13


def aperture_corners(blades, rotation, ratio):
    """The aperture's outline, counter-clockwise: a 720-gon for a round one (area within 2e-5
    of the disk's), else the regular polygon with corners at rotation + (2k + 1) pi / blades on
    the unit circle (Cycles' regular_polygon_sample); x divided by ratio."""
    n = 720 if blades < 3 else blades
    angles = rotation + (2 * np.arange(n) + 1) * math.pi / n
    return np.column_stack([np.cos(angles) / ratio, np.sin(angles)])


def clipped_area(corners, x0, x1, y0, y1):
    """Area of the convex polygon ``corners`` inside the box (Sutherland-Hodgman clipping)."""
    points = [tuple(p) for p in corners]
    for axis, bound, above in ((0, x0, True), (0, x1, False), (1, y0, True), (1, y1, False)):
        inside = (lambda p: p[axis] >= bound) if above else (lambda p: p[axis] <= bound)
        clipped = []
        for k, p in enumerate(points):
            q = points[k - 1]
            if inside(p) != inside(q):
                t = (bound - q[axis]) / (p[axis] - q[axis])
                clipped.append((q[0] + t * (p[0] - q[0]), q[1] + t * (p[1] - q[1])))
            if inside(p):
                clipped.append(p)
        points = clipped
        if not points:
            return 0.0
    x, y = np.array(points).T
    return 0.5 * abs(float(x @ np.roll(y, -1) - y @ np.roll(x, -1)))


@pytest.mark.parametrize("blades,rotation,ratio", [(0, 0.0, 1.0), (5, 0.35, 1.6), (6, 1.0, 0.7)],
                         ids=["disk", "pentagon_squeezed", "hexagon_stretched"])
def test_aperture_samples_are_uniform_on_the_aperture(session, blades, rotation, ratio):
    """Depth of field's lens points: uniform over the disk or the turned regular polygon (as
    Cycles' camera_sample_aperture draws them), squeezed by the anamorphic ratio; none outside."""
    r = session.test_sampling(TEST_APERTURE, [blades, rotation, ratio, 0.0, 0.0], N, seed=SEED + 1300 + blades)
    points = r[:, 0, :2].astype(np.float64)
    corners = aperture_corners(blades, rotation, ratio)
    # Inside every edge (counter-clockwise: the point is left of it), up to float rounding.
    edges = np.roll(corners, -1, axis=0) - corners
    # Edge by edge: all points against all 720 edges at once took 46 s (a 1.7 GB array).
    lowest = min(float((e[0] * (points[:, 1] - c[1]) - e[1] * (points[:, 0] - c[0])).min())
                 for e, c in zip(edges, corners))
    slack = 1e-5 if blades >= 3 else 2e-5 + 1.0 - math.cos(math.pi / 720)  # the 720-gon's chords
    assert lowest >= -slack
    cells = 24
    xs, ys = np.linspace(-1.0 / ratio, 1.0 / ratio, cells + 1), np.linspace(-1.0, 1.0, cells + 1)
    counts, _, _ = np.histogram2d(points[:, 0], points[:, 1], bins=[xs, ys])
    areas = np.array([[clipped_area(corners, xs[i], xs[i + 1], ys[j], ys[j + 1]) for j in range(cells)]
                      for i in range(cells)])
    check_multinomial(f"aperture blades={blades} rotation={rotation} ratio={ratio}", counts, areas)
