"""Guiding mixtures fitted on the device (issue 13; shaders/techniques/guiding/fit.comp,
native/src/techniques/guiding/device_fit.h) against the host fit (em.cpp), which stays the
oracle: the stable counting sort by region; one EM step equal within float tolerance; the
converged log-likelihood within 1%; the same lobe count after split and merge; parallax
targets; stepwise statistics across frames; several regions in one dispatch; run-to-run
determinism; the records the sampler reads. The device sees what the trace loop writes
(float32, octahedral directions), so the host fit gets the same rounded inputs. Seeded.
"""
from __future__ import annotations

import math

import numpy as np
import pytest

from parallax_core import _native
from test_guiding_vmm import THREE, mixture, two_lobes, unit

g = _native.guiding
DEVICE = "cpu"  # lavapipe


def rounded(d, w, p):
    """The directions, weights and pdfs as the device reads them from GuidingSample records."""
    d = g.unpack_directions(g.pack_directions(d))
    return d, np.asarray(w, np.float32).astype(np.float64), np.asarray(p, np.float32).astype(np.float64)


def records(d, w, p, positions=None, distances=None, regions=None):
    n = len(d)
    positions = np.zeros((n, 3)) if positions is None else positions
    distances = np.full(n, 1e30) if distances is None else distances
    regions = np.zeros(n, np.uint32) if regions is None else np.asarray(regions, np.uint32)
    return g.make_samples(positions, d, p, w, distances, regions)


def options(**kw):
    o = g.FitOptions()
    for k, v in kw.items():
        setattr(o, k, v)
    return o


def host_fit(batches, o, parallax=False, pivot=(0.0, 0.0, 0.0)):
    """The host fit of the same batches (each (d, w, p[, positions, distances]))."""
    m = g.Mixture()
    rep = None
    for b in batches:
        d, w, p = rounded(*b[:3])
        kw = dict(positions=b[3], distances=b[4], parallax=True) if parallax else {}
        rep = m.fit(d, w, p, o, pivot=np.asarray(pivot, np.float64), **kw)
    return m, rep


def weighted_ll(mix, d, w):
    d = g.unpack_directions(g.pack_directions(d))
    return float(np.sum(w * np.log(g.vmm_pdf(mix, d))) / np.sum(w))


def assert_same_mixture(dev, cpu, atol=2e-4, rtol=2e-3):
    assert len(dev["weights"]) == len(cpu["weights"])
    np.testing.assert_allclose(dev["weights"], cpu["weights"], atol=atol)
    np.testing.assert_allclose(dev["mus"], cpu["mus"], atol=atol)
    np.testing.assert_allclose(dev["kappas"], cpu["kappas"], rtol=rtol)


def three_lobes(rng, n):
    d = g.vmm_sample(THREE, rng.random((n, 3)))
    return d, np.ones(n), g.vmm_pdf(THREE, d)


def bimodal(rng, n):
    _, d, p = two_lobes(rng, n)
    return d, np.ones(n), p


def random_set(rng, n):
    """Uniform directions, log-normal weights, a quarter of them zero (unlit samples)."""
    d = unit(rng.normal(size=(n, 3)))
    w = np.exp(rng.normal(size=n)) * (rng.random(n) > 0.25)
    return d, w, np.full(n, 1 / (4 * math.pi))


@pytest.mark.parametrize("n, count", [(3000, 5), (70_000, 300)])
def test_counting_sort_is_stable_and_drops_bad_records(n, count):
    # 70k samples in 300 regions: 547 blocks of 128, 165k counts, 161 scan tiles of 1024 (over
    # the 64 threads of one workgroup: the tile prefixes' pass runs three per thread, the last
    # tile short).
    rng = np.random.default_rng(90)
    d, w, p = random_set(rng, n)
    regions = rng.integers(0, count, n)
    regions[::97] = count + 4  # no such region
    p[::89] = 0.0      # an empty slot
    w[::83] = np.nan   # rejected, as add_samples rejects it
    f = g.DeviceFit(count, options(), device=DEVICE)
    f.fit(records(d, w, p, regions=regions))
    starts, order = f.bins()
    # region r's lit samples in bin 2 r, its unlit ones in bin 2 r + 1 (the EM reads only the lit)
    bins = np.where((regions < count) & (p > 0) & np.isfinite(w), 2 * regions + (w == 0), 2 * count)
    want = np.argsort(bins, kind="stable")
    np.testing.assert_array_equal(order, want)
    np.testing.assert_array_equal(starts, np.concatenate([[0], np.cumsum(np.bincount(bins, minlength=2 * count + 1))]))


def test_pivots_average_every_sample_over_the_position_parts():
    """POSITIONS sums each region's samples (lit and unlit) in parts, a workgroup each, when
    regions are few and full (here 4 parts: 53k samples in 3 regions); the pivot is the mean of
    all of a region's positions, over frames, whatever the parts' boundaries."""
    rng = np.random.default_rng(97)
    sizes = [40_000, 13_001, 3]
    f = g.DeviceFit(4, options(), device=DEVICE, min_samples=100_000)  # no fit: only the pivots
    seen = [[] for _ in sizes]
    for _ in range(2):
        regions = np.repeat(np.arange(len(sizes)), sizes)
        n = len(regions)
        x = rng.random((n, 3)) + regions[:, None] * 10.0
        d, w, p = random_set(rng, n)
        order = rng.permutation(n)
        f.fit(records(d[order], w[order], p[order], positions=x[order], regions=regions[order]))
        for r in range(len(sizes)):
            seen[r].append(x[regions == r])
    for r in range(len(sizes)):
        st = f.state(r)
        assert st["fits"] == 0 and st["samples"] == 2 * sizes[r]
        np.testing.assert_allclose(st["pivot"], np.concatenate(seen[r]).mean(0), rtol=2e-6, atol=1e-5)
    assert f.state(3)["samples"] == 0


def test_one_em_step_matches_the_host_fit_in_several_regions():
    """Three regions in one dispatch (a constructed three-lobe set, a random weighted set and a
    bimodal one), each against its own host fit; then a second frame, with the first frame's
    statistics decayed (stepwise EM)."""
    rng = np.random.default_rng(91)
    o = options(max_iterations=1, split_merge=False)
    sets = [[three_lobes(rng, 4000), random_set(rng, 3000), bimodal(rng, 2000)],
            [three_lobes(rng, 3000), random_set(rng, 2000), bimodal(rng, 2500)]]
    f = g.DeviceFit(3, o, device=DEVICE)
    for frame in range(2):
        recs = np.concatenate([records(*s, regions=np.full(len(s[0]), r)) for r, s in enumerate(sets[frame])])
        order = rng.permutation(len(recs))  # interleaved: the sort gathers each region's samples
        f.fit(np.ascontiguousarray(recs[order]))
        for r in range(3):
            # the host fit sees the region's samples in the same (original) order
            cpu, rep = host_fit([sets[i][r] for i in range(frame + 1)], o)
            dev = f.mixture(r)
            assert_same_mixture(dev, cpu.mixture)
            st = f.state(r)
            assert st["fits"] == frame + 1 and st["iterations"] == 1 and st["components"] == cpu.count
            assert st["log_likelihood"] == pytest.approx(rep["log_likelihood"], rel=1e-4, abs=1e-4)


def test_lit_samples_wait_across_frames_until_min_samples():
    """A region below min_samples keeps its lit samples on the device (field.cpp's reservoir):
    three frames of 30 samples (a third unlit) with min_samples 50 fit once, on all 60 lit
    samples of the first two frames then the third's, as the host fits their concatenation."""
    rng = np.random.default_rng(96)
    frames = []
    for _ in range(3):
        d, w, p = random_set(rng, 30)
        w = np.exp(rng.normal(size=30))
        w[:10] = 0.0
        frames.append((d, w, p))
    o = options(max_iterations=1, split_merge=False, initial_components=2)
    f = g.DeviceFit(1, o, device=DEVICE, min_samples=50)
    f.fit(records(*frames[0]))
    assert f.state(0)["fits"] == 0 and f.state(0)["pending"] == 20 and f.state(0)["components"] == 0
    f.fit(records(*frames[1]))
    assert f.state(0)["fits"] == 0 and f.state(0)["pending"] == 40
    f.fit(records(*frames[2]))
    st = f.state(0)
    assert st["fits"] == 1 and st["pending"] == 0 and st["samples"] == 90
    lit = [np.concatenate([fr[i][fr[1] > 0] for fr in frames]) for i in range(3)]
    cpu, _ = host_fit([tuple(lit)], o)
    assert_same_mixture(f.mixture(0), cpu.mixture)


def test_converged_log_likelihood_within_one_percent():
    rng = np.random.default_rng(92)
    for d, w, p in (three_lobes(rng, 20_000), random_set(rng, 20_000)):
        o = options(split_merge=False)
        cpu, rep = host_fit([(d, w, p)], o)
        f = g.DeviceFit(1, o, device=DEVICE)
        f.fit(records(d, w, p))
        assert f.state(0)["iterations"] >= 2
        ll_cpu, ll_dev = weighted_ll(cpu.mixture, d, w), weighted_ll(f.mixture(0), d, w)
        assert abs(ll_dev - ll_cpu) <= 0.01 * abs(ll_cpu), (ll_dev, ll_cpu)


def test_split_and_merge_give_the_same_lobe_count():
    rng = np.random.default_rng(93)
    # split: one lobe on a bimodal set becomes two
    truth, d, p = two_lobes(rng, 40_000)
    o = options(max_components=4, initial_components=1)
    cpu, rep = host_fit([(d, np.ones(len(d)), p)], o)
    f = g.DeviceFit(1, o, device=DEVICE)
    f.fit(records(d, np.ones(len(d)), p))
    st = f.state(0)
    assert rep["splits"] == st["splits"] == 1 and cpu.count == st["components"] == 2
    dev = f.mixture(0)
    for mu in truth["mus"]:
        assert np.max(dev["mus"] @ mu) > math.cos(math.radians(3.0))
    # merge: the default start (8 lobes) on three lobes merges duplicates
    d, w, p = three_lobes(rng, 60_000)
    cpu, rep = host_fit([(d, w, p)], options())
    f = g.DeviceFit(1, options(), device=DEVICE)
    f.fit(records(d, w, p))
    st = f.state(0)
    assert rep["merges"] >= 1 and st["merges"] == rep["merges"] and st["components"] == cpu.count
    ll_cpu, ll_dev = weighted_ll(cpu.mixture, d, w), weighted_ll(f.mixture(0), d, w)
    assert abs(ll_dev - ll_cpu) <= 0.01 * abs(ll_cpu), (ll_dev, ll_cpu)


def test_parallax_targets_match_the_host_fit():
    """A point light seen from all over a region: one lobe at kappa_max aiming at the light,
    its target where the host fit puts it; the pivot is the samples' mean position."""
    rng = np.random.default_rng(94)
    n = 20_000
    x = rng.random((n, 3))
    light = np.array([0.5, 0.5, 3.0])
    dist = np.linalg.norm(light - x, axis=1)
    d = (light - x) / dist[:, None]
    o = options(initial_components=2, split_merge=False)
    f = g.DeviceFit(1, o, parallax=True, device=DEVICE)
    f.fit(records(d, np.ones(n), np.ones(n), positions=x, distances=dist))
    pivot = np.array(f.state(0)["pivot"])
    np.testing.assert_allclose(pivot, x.mean(0), atol=1e-4)
    cpu, _ = host_fit([(d, np.ones(n), np.ones(n), x, dist)], o, parallax=True, pivot=pivot)
    dev, want = f.mixture(0), cpu.mixture
    k, kc = int(np.argmax(dev["weights"])), int(np.argmax(want["weights"]))
    assert dev["kappas"][k] == pytest.approx(want["kappas"][kc], rel=1e-2) and dev["kappas"][k] > 1e4
    target = dev["pivot"] + dev["distances"][k] * dev["mus"][k]
    np.testing.assert_allclose(target, want["pivot"] + want["distances"][kc] * want["mus"][kc], atol=2e-3)
    np.testing.assert_allclose(target, light, atol=5e-3)
    # the sampler's record: the target and a finite distance
    lobe = f.lobes()[k]
    np.testing.assert_allclose(lobe[8:11], target, atol=1e-4)
    assert lobe[7] == pytest.approx(dev["distances"][k], rel=1e-5)


def test_deterministic_and_the_records_the_sampler_reads():
    rng = np.random.default_rng(95)
    d, w, p = three_lobes(rng, 30_000)
    rec = records(d, w, p, regions=rng.integers(0, 2, len(d)))
    runs = []
    for _ in range(2):
        f = g.DeviceFit(2, options(), device=DEVICE)
        f.fit(rec)
        f.fit(rec)
        runs.append((f.lobes(), f.regions(), f.mixture(0), f.mixture(1)))
    np.testing.assert_array_equal(runs[0][0], runs[1][0])
    np.testing.assert_array_equal(runs[0][1], runs[1][1])
    lobes, regions = runs[0][0], runs[0][1].view(np.uint32)
    for r in range(2):
        mix = runs[0][2 + r]
        k = len(mix["weights"])
        assert regions[r, 3] == k and regions[r, 7] == 2  # lobe_count, fits
        np.testing.assert_allclose(lobes[16 * r: 16 * r + k], g.gpu_lobes(mix, parallax=False), rtol=2e-5, atol=2e-6)
        assert not lobes[16 * r + k: 16 * (r + 1)].any()


def test_refinement_matches_the_host_field():
    """Adaptive refinement (device_fit.h refine, the REFINE pass) against the host field's
    (field.cpp fit): the same frames split the same regions at the same planes (threshold,
    only regions with a mixture, region order, the max_regions cap); a child inherits the
    mixture and records with half of the statistics on both sides, the pending lit samples
    go to the half holding them, their unlit count in proportion; the next fits agree. The
    threshold counts lit samples (non-zero weight) only."""
    rng = np.random.default_rng(97)
    p = g.GuidingParams()
    p.region_splits, p.min_samples, p.region_threshold, p.max_regions = 1, 64, 230, 4
    p.max_components, p.split_merge, p.parallax = 4, 0, 0
    field = g.GuidingField(np.zeros(3), np.array([4.0, 1.0, 1.0]), p, seed=1, options=options(max_iterations=1),
                           threads=1)
    f = g.DeviceFit.for_field(field, device=DEVICE)

    def frame(boxes):
        """Samples uniform in each (x0, x1, count, unlit) slab, three-lobe directions."""
        parts = []
        for x0, x1, n, unlit in boxes:
            x = rng.random((n, 3))
            x[:, 0] = x0 + (x1 - x0) * x[:, 0]
            d, w, pdf = three_lobes(rng, n)
            w[:unlit] = 0.0
            parts.append((x, d, w, pdf))
        x, d, w, pdf = (np.concatenate(c) for c in zip(*parts))
        return records(d, w, pdf, positions=x, regions=field.region_of(x)), x, w

    def step(boxes, splits):
        recs, x, w = frame(boxes)
        field.add_samples(recs)
        f.fit(recs)
        before = [f.state(r) for r in range(f.region_count)]
        assert field.fit()["refinements"] == splits
        assert f.refine(p.region_threshold, p.max_regions) == splits
        assert f.region_count == field.region_count == len(before) + splits
        np.testing.assert_array_equal(f.nodes(), field.nodes())  # the same tree, planes included
        dev, host = f.regions(), field.regions()
        np.testing.assert_array_equal(dev[:, [0, 1, 2, 4, 5, 6]], host[:, [0, 1, 2, 4, 5, 6]])  # boxes
        return before, x, w

    # Frame 1: region 1 (300 lit > 230, fitted) splits; region 0 (200 lit) does not.
    before, _, _ = step([(0.0, 2.0, 250, 50), (2.0, 4.0, 350, 50)], 1)
    s1, s2 = f.state(1), f.state(2)
    assert s1["components"] == s2["components"] == before[1]["components"] > 0
    assert s1["stat_weight"] == s2["stat_weight"] == pytest.approx(0.5 * before[1]["stat_weight"], rel=1e-6)
    assert s1["stat_count"] == pytest.approx(0.5 * before[1]["stat_count"], rel=1e-6)
    assert s1["received"] == s2["received"] == 0 and f.state(0)["received"] == 200
    assert s2["samples"] == before[1]["samples"] == 350 and s2["fits"] == before[1]["fits"] == 1
    # the learnt probability's sums, halved (no contributions here: guiding_prob, as the host's)
    assert s1["selection_samples"] == s2["selection_samples"] == 0.5 * before[1]["selection_samples"] == 175
    assert s1["prob"] == s2["prob"] == field.region_info(2)["prob"] == 0.5
    lobes = f.lobes()
    np.testing.assert_array_equal(lobes[32:48], lobes[16:32])  # the sampler's records: inherited
    np.testing.assert_array_equal(f.regions()[2, 8:11], f.regions()[1, 8:11])  # pivot
    for r in range(3):
        assert_same_mixture(f.mixture(r), field.mixture(r))
    # Frame 2: region 0 receives 60, 40 of them lit (240 lit > 230): too few to fit, they
    # wait; it splits and they are partitioned. Region 2 (300 lit since its split) would split too,
    # but max_regions (4) stops it: region order decides.
    before, x, w = step([(0.0, 2.0, 60, 20), (3.0, 4.0, 320, 20)], 1)
    assert before[0]["pending"] == 40 and before[0]["pending_zero"] == pytest.approx(20.0)
    plane = field.region_info(3)["min"][0]
    upper = int(np.sum((x[:60, 0] >= plane) & (w[:60] > 0)))
    assert 0 < upper < 40
    s0, s3 = f.state(0), f.state(3)
    assert (s0["pending"], s3["pending"]) == (40 - upper, upper)
    assert (field.region_info(0)["pending"], field.region_info(3)["pending"]) == (40 - upper, upper)
    assert s3["pending_zero"] == pytest.approx(20.0 * upper / 40, rel=1e-6)
    assert s0["pending_zero"] + s3["pending_zero"] == pytest.approx(20.0, rel=1e-6)
    # Frame 3: every region fits (the halves on their pending samples and half the statistics).
    step([(0.0, 1.0, 120, 20), (1.0, 2.0, 120, 20), (2.0, 3.0, 120, 20), (3.0, 4.0, 120, 20)], 0)
    for r in range(4):
        assert f.state(r)["pending"] == 0 and f.state(r)["fits"] == field.region_info(r)["fits"]
        dev, host = f.mixture(r), field.mixture(r)
        assert_same_mixture(dev, host, atol=1e-3, rtol=1e-2)
        np.testing.assert_allclose(dev["pivot"], host["pivot"], atol=1e-5)
    # The session's stats: what children inherited is counted once.
    samples, fits = f.inherited
    assert sum(f.state(r)["samples"] for r in range(4)) - samples == 600 + 380 + 480
    assert sum(f.state(r)["fits"] for r in range(4)) - fits == field.fit()["region_fits"] == 2 + 1 + 4


# ---- the learnt guiding probability (selection.h; fit.comp score_selection) ------------------
LIGHT = np.array([0.5, 0.5, 3.0])  # a small light above the unit box


def selection_frame(rng, n, base, bsdf_spread=False):
    """n records in the unit box, directions sampled by a cosine-free hemisphere BSDF (pdf =
    bsdf_pdf = 1 / 2 pi). A record within a narrow cone towards LIGHT gains contribution 1 (at the
    light's distance), any other `base`: base 0 is a narrow light only, large base light spread
    like the BSDF's density."""
    x = rng.random((n, 3))
    u = rng.random((n, 2))
    z, phi = u[:, 0], 2 * math.pi * u[:, 1]
    r = np.sqrt(1 - z * z)
    d = np.stack([r * np.cos(phi), r * np.sin(phi), z], 1)
    pdf = np.full(n, 1 / (2 * math.pi))
    to = LIGHT - x
    dist = np.linalg.norm(to, axis=1)
    lit = np.sum(d * to, 1) / dist > 0.98
    c = np.where(lit, 1.0, base)
    return x, d, pdf, c / pdf, c, np.where(lit, dist, 1e30)


def selection_records(frame, regions):
    x, d, pdf, w, c, dist = frame
    return g.make_samples(x, d, pdf, w, dist, np.asarray(regions, np.uint32), bsdf_pdfs=pdf, contributions=c)


def field_and_device(**kw):
    p = g.GuidingParams()
    p.region_splits, p.min_samples, p.region_threshold, p.parallax = 1, 64, 0, 1
    for k, v in kw.items():
        setattr(p, k, v)
    field = g.GuidingField(np.zeros(3), np.ones(3), p, seed=1, threads=1)
    return p, field, g.DeviceFit.for_field(field, device=DEVICE)


def assert_same_selection(f, field, r):
    """The device's record holds the region's own choice (the host field's sampler gets 0
    everywhere where guiding does not pay as a whole; the device leaves that to the session,
    which then drops the guided pipeline: DeviceFit.mixture_sampled)."""
    dev, host = f.state(r), field.region_info(r)
    assert dev["prob"] == pytest.approx(host["chosen_prob"], abs=1e-6)
    assert dev["score_bsdf"] == pytest.approx(host["score_bsdf"], rel=1e-4)
    assert dev["score_chosen"] == pytest.approx(host["score_chosen"], rel=1e-4)
    np.testing.assert_array_equal(f.regions()[r, 12:15], np.float32([dev["prob"], dev["score_bsdf"],
                                                                      dev["score_chosen"]]))


@pytest.mark.parametrize("base, probs", [(0.0, (0.8, 0.9)), (0.05, (0.6, 0.8)), (0.08, (0.0, 0.7))])
def test_learnt_probability_matches_the_host_field(base, probs):
    """A narrow light over a BSDF of uniform density: the device fit learns the host field's
    probability (the mixture's density at each record's own position, parallax targets), over
    frames (the sums decayed) and through refinement (halved sums, the choice inherited); more
    light outside the cone lowers it (an interior optimum of the grid)."""
    rng = np.random.default_rng(98)
    p, field, f = field_and_device(region_threshold=5000, max_regions=4)
    for frame in range(3):
        fr = selection_frame(rng, 20_000, base)
        rec = selection_records(fr, field.region_of(fr[0]))
        field.add_samples(rec)
        field.fit()  # and refines
        f.fit(rec)
        before = [f.state(r) for r in range(f.region_count)]
        for r in range(f.region_count):
            assert_same_selection(f, field, r)  # a split region's choice and moments stay
        split = f.refine(p.region_threshold, p.max_regions)
        assert f.region_count == field.region_count
        for r in range(f.region_count):
            assert_same_selection(f, field, r)
        if split and frame == 0:  # every record is lit with base > 0: both regions split
            for parent, child in ((0, 2), (1, 3)):
                a, b = f.state(parent), f.state(child)
                assert a["selection_samples"] == b["selection_samples"] == 0.5 * before[parent]["selection_samples"]
                np.testing.assert_array_equal(a["selection_scores"], b["selection_scores"])
                np.testing.assert_allclose(a["selection_scores"], 0.5 * np.array(before[parent]["selection_scores"]),
                                           rtol=1e-7)
                assert a["prob"] == b["prob"] == before[parent]["prob"]
    assert (f.region_count == 4) == (base > 0)
    learnt = [f.state(r)["prob"] for r in range(f.region_count)]
    for r in range(f.region_count):
        assert_same_selection(f, field, r)
    assert probs[0] - 1e-6 <= max(learnt) <= probs[1] + 1e-6, learnt
    assert f.guiding_pays == field.guiding_pays and f.mixture_sampled == (f.guiding_pays and max(learnt) > 0)


def test_light_spread_like_the_bsdf_learns_zero():
    """Contribution spread like the BSDF's density: no candidate beats BSDF sampling alone by the
    margin, prob 0 everywhere, as the host's; guiding does not pay."""
    rng = np.random.default_rng(99)
    _, field, f = field_and_device()
    for _ in range(2):
        fr = selection_frame(rng, 20_000, 1.0)
        rec = selection_records(fr, field.region_of(fr[0]))
        field.add_samples(rec)
        field.fit()
        f.fit(rec)
    for r in range(2):
        assert f.state(r)["prob"] == 0.0 and f.state(r)["selection_weight"] > 0.0
        assert_same_selection(f, field, r)
    assert not f.guiding_pays and not field.guiding_pays and not f.mixture_sampled


def test_the_global_rule_weighs_every_region():
    """GuidingField::guiding_pays on the device fit's tally: one region gains from its narrow
    light, the other, with far more light spread like the BSDF, loses the margin's cost on many
    more samples: guiding does not pay as a whole (the host then zeroes every prob; the session
    drops the guiding pipeline, the device's records keep the region's choice)."""
    rng = np.random.default_rng(100)
    _, field, f = field_and_device()
    for _ in range(2):
        cone, spread = selection_frame(rng, 20_000, 0.0), selection_frame(rng, 20_000, 1.0)
        cone[0][:, 0] *= 0.5          # region 0: x < 0.5
        spread[0][:, 0] = 0.5 + 0.5 * spread[0][:, 0]  # region 1
        recs = np.concatenate([selection_records(fr, field.region_of(fr[0])) for fr in (cone, spread)])
        field.add_samples(recs)
        field.fit()
        f.fit(recs)
    assert f.state(0)["prob"] == pytest.approx(0.9) and f.state(1)["prob"] == 0.0
    assert not field.guiding_pays and not f.guiding_pays and not f.mixture_sampled
    assert field.region_info(0)["prob"] == 0.0
    for r in range(2):
        assert f.state(r)["score_bsdf"] == pytest.approx(field.region_info(r)["score_bsdf"], rel=1e-4)
        assert f.state(r)["score_chosen"] == pytest.approx(field.region_info(r)["score_chosen"], rel=1e-4)


def test_learnt_probability_is_deterministic():
    rng = np.random.default_rng(101)
    frames = [selection_frame(rng, 30_000, 0.05) for _ in range(2)]
    recs = [selection_records(fr, rng.integers(0, 3, len(fr[0]))) for fr in frames]
    runs = []
    for _ in range(2):
        f = g.DeviceFit(3, options(), parallax=True, device=DEVICE)
        for rec in recs:
            f.fit(rec)
        runs.append((f.regions(), [f.state(r)["selection_scores"] for r in range(3)]))
    np.testing.assert_array_equal(runs[0][0], runs[1][0])
    np.testing.assert_array_equal(runs[0][1], runs[1][1])
    assert (runs[0][0][:, 12] > 0).all()


def test_guiding_prob_without_adaptive_prob_or_before_learning():
    """adaptive_prob off: every region samples with guiding_prob, nothing is learnt and guiding
    pays; on, a region that has not fitted yet (below min_samples) keeps guiding_prob, as the
    host field's records."""
    rng = np.random.default_rng(102)
    fr = selection_frame(rng, 4000, 0.0)
    regions = (fr[0][:, 0] > 0.02).astype(np.uint32)  # region 0: ~80 records, ~2 lit
    rec = selection_records(fr, regions)
    off = g.DeviceFit(2, options(), device=DEVICE, min_samples=32, prob=0.3, adaptive_prob=False)
    on = g.DeviceFit(2, options(), device=DEVICE, min_samples=32, prob=0.3)
    for f in (off, on):
        f.fit(rec)
        f.fit(rec)
    np.testing.assert_array_equal(off.regions()[:, 12:15], np.float32([[0.3, 0, 0], [0.3, 0, 0]]))
    assert off.state(1)["fits"] == 2 and off.state(1)["selection_samples"] == 0.0 and off.guiding_pays
    assert on.state(0)["fits"] == 0 and on.state(0)["prob"] == pytest.approx(0.3)
    assert on.state(1)["fits"] == 2 and on.state(1)["prob"] == pytest.approx(0.9)
    # the host field's choice with adaptive_prob off, through DeviceFit.for_field
    _, field, f = field_and_device(adaptive_prob=0, prob=0.25)
    rec = selection_records(fr, field.region_of(fr[0]))
    field.add_samples(rec)
    field.fit()
    f.fit(rec)
    for r in range(2):
        assert f.state(r)["prob"] == field.region_info(r)["prob"] == pytest.approx(0.25)


def test_bad_input_is_a_clear_error():
    with pytest.raises(ValueError, match="regions"):
        g.DeviceFit(0, device=DEVICE)
    o = g.FitOptions()
    o.max_components = 17
    with pytest.raises(ValueError, match="max_components"):
        g.DeviceFit(1, o, device=DEVICE)
    f = g.DeviceFit(1, device=DEVICE)
    with pytest.raises(ValueError, match="records"):
        f.fit(np.zeros((4, 7), np.uint32))
    with pytest.raises(ValueError, match="region"):
        f.mixture(1)
