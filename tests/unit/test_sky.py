"""parallax_core.sky (Blender's Sky Texture in numpy) without Blender: shapes, conventions,
symmetry and physically sensible behaviour. tests/addon/test_parity_sky.py compares it with
Cycles' renders."""
import importlib.util
import math
import os
import re

import numpy as np
import pytest

from parallax_core import sky as S


def _directions(elevation_deg, azimuth_deg):
    """Unit directions (..., 3) from elevations above the horizon and azimuths atan2(y, x)."""
    e, a = np.radians(elevation_deg), np.radians(azimuth_deg)
    return np.stack(np.broadcast_arrays(np.cos(e) * np.cos(a), np.cos(e) * np.sin(a), np.sin(e)), -1)


def _sphere(n_theta=24, n_phi=48):
    theta, phi = np.meshgrid((np.arange(n_theta) + 0.5) / n_theta * math.pi,
                             (np.arange(n_phi) + 0.5) / n_phi * 2 * math.pi, indexing="ij")
    return np.stack([np.sin(theta) * np.cos(phi), np.sin(theta) * np.sin(phi), np.cos(theta)], -1)


@pytest.fixture(scope="module")
def skies():
    """One sky of each type (default settings but for a tilted, rotated sun)."""
    params = dict(sun_elevation=math.radians(25), sun_rotation=math.radians(40))
    return {"SINGLE_SCATTERING": S.Sky(S.SkyParams("SINGLE_SCATTERING", **params)),
            "MULTIPLE_SCATTERING": S.Sky(S.SkyParams("MULTIPLE_SCATTERING", **params)),
            "PREETHAM": S.Sky(S.SkyParams("PREETHAM", sun_direction=(0.4, 0.7, 0.5), turbidity=3.0))}


def test_shapes_and_finite_values(skies):
    dirs = _sphere()
    for name, sky in skies.items():
        rgb = sky.radiance(dirs)
        assert rgb.shape == dirs.shape, name
        assert np.isfinite(rgb).all() and (rgb >= 0).all(), name
        assert rgb[:12].mean() > 0.01, name  # the upper hemisphere is lit
        flat = sky.radiance(dirs.reshape(-1, 3))
        assert flat.shape == (dirs.size // 3, 3)
        np.testing.assert_array_equal(flat.reshape(dirs.shape), rgb)
        # Directions need not be unit length.
        np.testing.assert_allclose(sky.radiance(dirs * 3.7), rgb, rtol=1e-12, atol=0)


def test_lut_shape_and_mirror(skies):
    for name in ("SINGLE_SCATTERING", "MULTIPLE_SCATTERING"):
        lut = skies[name].lut
        assert lut.shape == (256, 512, 3)
        assert np.isfinite(lut).all() and (lut >= 0).all()
        np.testing.assert_array_equal(lut, lut[:, ::-1])  # mirrored about the sun's azimuth


def test_symmetric_about_the_suns_azimuth(skies):
    for name, sky in skies.items():
        sun = sky.sun_direction()
        sun_azimuth = math.degrees(math.atan2(sun[1], sun[0]))
        offsets = np.array([3.0, 17.0, 60.0, 121.0, 178.0])
        elevations = np.array([-20.0, 0.5, 10.0, 45.0, 80.0])[:, None]
        left = sky.radiance(_directions(elevations, sun_azimuth + offsets))
        right = sky.radiance(_directions(elevations, sun_azimuth - offsets))
        np.testing.assert_allclose(left, right, rtol=1e-6, atol=1e-9, err_msg=name)


def test_brightest_near_the_sun(skies):
    """At the sun's elevation the sky peaks towards the sun's azimuth (forward scattering):
    checks the azimuth convention (sun rotation 0 puts the sun towards +Y, rotation turns it
    clockwise seen from above, towards +X)."""
    azimuths = np.arange(0.0, 360.0, 2.0)
    for name, sky in skies.items():
        sun = sky.sun_direction()
        elevation = math.degrees(math.asin(sun[2]))
        luminance = sky.radiance(_directions(elevation + 3.0, azimuths)) @ [0.2126, 0.7152, 0.0722]
        peak = azimuths[luminance.argmax()]
        sun_azimuth = math.degrees(math.atan2(sun[1], sun[0])) % 360
        assert abs((peak - sun_azimuth + 180) % 360 - 180) <= 4.0, (name, peak, sun_azimuth)
    # The node's rotation: 40 degrees from +Y towards +X.
    expected = _directions(25.0, 90.0 - 40.0)
    np.testing.assert_allclose(skies["MULTIPLE_SCATTERING"].sun_direction(), expected, atol=1e-12)


def test_sun_angles_wrap_as_cycles():
    """simplify_settings: past the zenith the sun comes down on the far side."""
    for elevation, rotation in ((math.radians(100), 0.3), (math.radians(-95), -1.0), (math.radians(370), 7.0),
                                (math.radians(15), 0.0), (math.radians(-30), 2.0)):
        e, r = S.wrap_sun_angles(elevation, rotation)
        assert -math.pi / 2 <= e <= math.pi / 2 and 0.0 < r <= 2 * math.pi
        # The same point of the sky as the plain formula (elevation, node rotation from +Y to +X).
        plain = np.array([math.cos(elevation) * math.sin(rotation), math.cos(elevation) * math.cos(rotation),
                          math.sin(elevation)])
        np.testing.assert_allclose(S._sun_vector(e, r), plain, atol=1e-9)
    assert S.wrap_sun_angles(math.radians(100), 0.0)[0] == pytest.approx(math.radians(80))


def test_sun_disc(skies):
    for name in ("SINGLE_SCATTERING", "MULTIPLE_SCATTERING"):
        sky = skies[name]
        direction, diameter, mean = sky.sun()
        np.testing.assert_allclose(direction, sky.sun_direction())
        assert np.linalg.norm(direction) == pytest.approx(1.0)
        assert diameter == pytest.approx(0.009512)
        assert mean.shape == (3,) and (mean > 0).all()
        # Far brighter than the sky, yellowish at 25 degrees.
        assert mean.min() > 1e4 * sky.radiance(direction).max()
        assert mean[0] > mean[2]
        # The disc: the mean of limb darkening 1 - 0.6 (1 - sqrt(1 - r^2)) over the disc is 0.8;
        # the elevation interpolation is about linear, so the centre's radiance times 0.8.
        centre = S._xyz_to_rgb(sky.disc_xyz(direction) + sky.sky_xyz(direction)) - sky.radiance(direction)
        np.testing.assert_allclose(mean, 0.8 * centre, rtol=2e-3)


@pytest.fixture(scope="module")
def low_and_high():
    """{sky type: (sun at 5 degrees, sun at 50 degrees)} for the scattering models."""
    return {t: tuple(S.Sky(S.SkyParams(t, sun_elevation=math.radians(e))) for e in (5.0, 50.0))
            for t in ("SINGLE_SCATTERING", "MULTIPLE_SCATTERING")}


def test_sun_is_redder_and_dimmer_near_the_horizon(low_and_high):
    for sky_type, skies in low_and_high.items():
        low, high = (sky.sun()[2] for sky in skies)
        assert low.sum() < high.sum(), sky_type
        assert low[0] / low[2] > 2 * high[0] / high[2], sky_type


def test_sun_none_cases():
    assert S.Sky(S.SkyParams("PREETHAM")).sun() is None
    assert S.Sky(S.SkyParams("MULTIPLE_SCATTERING", sun_disc=False)).sun() is None
    # Below the horizon as seen from the altitude (100 m: 0.32 degrees of dip): nothing drawn.
    assert S.Sky(S.SkyParams("MULTIPLE_SCATTERING", sun_elevation=math.radians(-5))).sun() is None
    assert S.Sky(S.SkyParams("SINGLE_SCATTERING", sun_elevation=math.radians(-1))).sun() is None
    assert S.Sky(S.SkyParams("SINGLE_SCATTERING", sun_intensity=0.0)).sun() is None
    # Single scattering draws the disc black once its top is below the horizon.
    assert S.Sky(S.SkyParams("SINGLE_SCATTERING", sun_elevation=math.radians(-0.3))).sun() is None
    # Partly below the Earth's limb: drawn, with the part below cut off.
    cut = S.Sky(S.SkyParams("MULTIPLE_SCATTERING", sun_elevation=math.radians(-0.2))).sun()
    assert cut is not None and cut[2][0] > 0


def test_physically_sensible(low_and_high):
    zenith, horizon = np.array([0.0, 0.0, 1.0]), _directions(2.0, -90.0)  # horizon away from the sun
    rec709_y = np.array([0.2126, 0.7152, 0.0722])
    for sky_type, (low, high) in low_and_high.items():
        z_low, z_high = low.radiance(zenith), high.radiance(zenith)
        assert z_high @ rec709_y > z_low @ rec709_y, sky_type  # a higher sun lights the zenith more
        assert z_high[2] > z_high[0], sky_type  # the clear sky is blue
        assert high.radiance(horizon)[2] > 0, sky_type
        # Below the horizon the sky fades (single scattering) or shows the lit haze and ground
        # (multiple scattering); it is never brighter than at the horizon.
        down = high.radiance(_directions(-60.0, -90.0)) @ rec709_y
        assert down < high.radiance(_directions(0.5, -90.0)) @ rec709_y, sky_type
    # More air: more Rayleigh scattering at the zenith.
    thin, thick = (S.Sky(S.SkyParams("MULTIPLE_SCATTERING", air_density=a)).radiance(zenith) for a in (0.5, 2.0))
    assert thick @ rec709_y > thin @ rec709_y


def test_preetham_zenith_is_the_fitted_zenith():
    """The Perez distribution is normalised to the fitted zenith luminance at the zenith."""
    t = 3.0
    sky = S.Sky(S.SkyParams("PREETHAM", sun_direction=(0.0, 2.0, 1.0), turbidity=t))
    theta = math.acos(1 / math.sqrt(5.0))
    chi = (4 / 9 - t / 120) * (math.pi - 2 * theta)
    zenith_y = 0.06 * ((4.0453 * t - 4.9710) * math.tan(chi) - 0.2155 * t + 2.4192)
    rgb = sky.radiance(np.array([0.0, 0.0, 1.0]))
    xyz = np.linalg.solve(S.XYZ_TO_REC709, rgb)
    assert xyz[1] == pytest.approx(zenith_y, rel=1e-9)


def test_unsupported_type():
    with pytest.raises(ValueError):
        S.Sky(S.SkyParams("HOSEK_WILKIE"))
    assert "HOSEK_WILKIE" in S.UNSUPPORTED_SKY_TYPES and "HOSEK_WILKIE" not in S.SKY_TYPES


def test_from_node_reads_raw_properties():
    class Node:
        sky_type, sun_disc, sun_size, sun_intensity = "MULTIPLE_SCATTERING", False, 0.02, 2.0
        sun_elevation, sun_rotation, altitude = 2.5, -7.0, 1500.0
        air_density, aerosol_density, ozone_density = 1.2, 0.5, 3.0
        sun_direction, turbidity = (0.0, 1.0, 1.0), 4.0
    params = S.SkyParams.from_node(Node())
    assert params == S.SkyParams("MULTIPLE_SCATTERING", False, 0.02, 2.0, 2.5, -7.0, 1500.0, 1.2, 0.5, 3.0,
                                 (0.0, 1.0, 1.0), 4.0)


def _ocio_config():
    spec = importlib.util.find_spec("bpy")
    if spec is None or not spec.submodule_search_locations:
        return None
    for root in spec.submodule_search_locations:
        for version in sorted(os.listdir(root)):
            path = os.path.join(root, version, "datafiles", "colormanagement", "config.ocio")
            if os.path.exists(path):
                return path
    return None


def test_xyz_matrix_is_the_configs_rec709_from_d65():
    """XYZ is D65-adapted (not illuminant E): XYZ_TO_REC709 maps D65 white to (1, 1, 1) and is
    the Linear Rec.709 matrix of Blender's OCIO config (up to Cycles' rounded AP0 matrix)."""
    white = np.linalg.solve(S.XYZ_TO_REC709, np.ones(3))
    np.testing.assert_allclose(white / white[1], [0.95047, 1.0, 1.08883], atol=5e-4)
    path = _ocio_config()
    if path is None:
        pytest.skip("bpy's OCIO config is not installed")
    text = open(path).read()
    block = text[text.index("name: Linear Rec.709"):]
    numbers = re.search(r"MatrixTransform>\s*\{matrix: \[([^\]]*)\]", block).group(1)
    matrix = np.array([float(v) for v in numbers.split(",")]).reshape(4, 4)[:3, :3]
    assert "aces_interchange: ACES2065-1" in text
    np.testing.assert_allclose(S.XYZ_TO_REC709, matrix, atol=2e-6)
