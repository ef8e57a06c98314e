"""Light sampling near emitters and among many (issue 14): an emissive triangle close to the
surface it lights (spherical-triangle sampling, its MIS density) rendered alike by pt, nee and
mis; and the light tree against picking by power on 1000 emissive triangles: the same image
(Z-test), less noise at equal samples. Tiny images; one scene family, so one pipeline per
method."""
import numpy as np

import parallax_core as pc
from parallax_core import scenes
from parallax_core.scene import Camera, Material, SceneData, World

from helpers import batches, means_agree, z_scores


def _close_triangle_scene(size=16):
    """A diffuse floor and a large emissive triangle standing on it (its lower edge 2 cm
    above), seen from above: floor points next to the edge see it fill half their sky."""
    floor = scenes.quad([(-2, -2, 0), (2, -2, 0), (2, 2, 0), (-2, 2, 0)], 0, "floor")
    tri = scenes._mesh([(-1.5, 0.3, 0.02), (1.5, 0.3, 0.02), (0.0, 0.6, 2.0)], [[0, 1, 2]], 1, "emitter")
    cam = Camera.look_at((0.0, -0.01, 5.0), (0.0, 0.0, 0.0), fov_y_degrees=50.0, width=size, height=size)
    mats = [Material("diffuse", (0.8, 0.8, 0.8)), Material("emission", emission=(4.0, 4.0, 4.0))]
    return SceneData([floor, tri], [], mats, [], [], World((0.0, 0.0, 0.0), 1.0), cam, size, size)


def test_close_emissive_triangle_pt_nee_mis_agree():
    sc = _close_triangle_scene()
    s = pc.Session(sc.width, sc.height)
    s.update(sc)
    res = {m: batches(sc, m, n_batches=6, spp=spp, session=s, max_depth=1)
           for m, spp in (("pt", 1024), ("nee", 64), ("mis", 64))}
    for a, b in (("pt", "mis"), ("nee", "mis"), ("pt", "nee")):
        z = z_scores(res[a].images, res[b].images, k=4)
        assert np.abs(z).max() < 5.0, f"{a} vs {b}: max |z| {np.abs(z).max():.2f}"
        ok, ma, mb, se = means_agree(res[a][3], res[b][3])
        assert ok, f"{a} vs {b}: image means {ma:.4f} vs {mb:.4f} (standard error {se:.4f})"


def rel_variance(mean, se):
    """relMSE of an unbiased estimate from its batch standard error: mean of se^2/(m^2+1e-3)."""
    return float((se**2 / (mean**2 + 1e-3)).mean())


def test_light_tree_beats_power_on_many_emitters():
    """The light_tree setting (Cycles' Light Tree checkbox) switches one session's scene
    between the tree and the power CDF without a new update."""
    sc = scenes.many_emitters(1000, 16, 16)
    s = pc.Session(sc.width, sc.height)
    s.update(sc)
    res = {}
    for name, on in (("tree", True), ("power", False)):
        res[name] = batches(sc, "nee", n_batches=8, spp=16, session=s, max_depth=1, light_tree=on)
        nodes = s.stats()["light_tree_nodes"]
        assert (nodes > 0) if on else (nodes == 0), f"{name}: {nodes} light tree nodes"
    s.update(sc)  # an update keeps the setting
    assert s.stats()["light_tree_nodes"] == 0
    z = z_scores(res["tree"].images, res["power"].images, k=4)
    assert np.abs(z).max() < 5.0, f"tree vs power: max |z| {np.abs(z).max():.2f}"
    ok, ma, mb, se = means_agree(res["tree"][3], res["power"][3])
    assert ok, f"tree vs power: image means {ma:.4f} vs {mb:.4f} (standard error {se:.4f})"
    ratio = rel_variance(*res["power"][:2]) / rel_variance(*res["tree"][:2])
    assert ratio > 5.0, f"relMSE at equal samples, power / tree = {ratio:.2f}"  # 13 measured
