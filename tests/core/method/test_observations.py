"""Observations (core.method.observations) on numpy scenes with known answers: the
per-pixel samples of a photo, what is removed and counted, the curvature map, the
view directions and subsets."""

import numpy as np
import pytest
from observing import lambert_table as _lambert_table
from observing import observe as _observe

from brdf_reconstruct.core.brdf import merl
from brdf_reconstruct.core.method import observations, reliable
from testkit import synthetic


# ------------------------------------------------------------------------ observations
def test_lambertian_rho_is_albedo_over_pi_with_rgb_irradiance(scene):
    truth, _ = scene
    light = synthetic.LIGHTS[0]
    E = np.array([2.0, 1.0, 0.5])
    photo = synthetic.photo(_lambert_table(0.4), truth, light, irradiance=E)
    s = _observe(photo, truth, light, irradiance=E)
    assert len(s) > 0.5 * truth.mask.size
    np.testing.assert_allclose(s.rho, 0.4 / np.pi, rtol=1e-12)
    # cells agree with the directions they came from
    np.testing.assert_array_equal(
        s.cells, merl.cells_from_dirs(merl.to_local(s.n, s.l), merl.to_local(s.n, s.v)))


def test_removals_are_counted(scene):
    truth, _ = scene
    light = np.array([0.0, 0.0, 1.0])
    photo = synthetic.photo(_lambert_table(), truth, light)
    vis = np.ones(truth.mask.shape)
    vis[:10] = 0.0  # shadowed rows
    region = np.zeros(truth.mask.shape, dtype=int)
    region[-5:] = -1  # background rows
    photo[20, 20] = np.nan
    photo[30, 30] = 50.0  # saturated
    s = _observe(photo, truth, light, visibility=vis, region=region,
                 settings=observations.ObservationSettings(clip_level=10.0))
    r = s.removed
    assert r["background"] == 5 * 96 and r["shadowed"] == 10 * 96
    assert r["nonfinite"] == 1 and r["saturated"] == 1
    assert len(s) + sum(r.values()) == truth.mask.size


def test_saturated_pixels_from_the_white_level_mask_are_removed_and_counted(scene):
    """A camera's saturation found on the file's codes (photo_io.Photo.saturated)
    rides along as a mask: those pixels are never fitted, whatever their value."""
    truth, _ = scene
    light = np.array([0.0, 0.0, 1.0])
    photo = synthetic.photo(_lambert_table(), truth, light)
    saturated = np.zeros(truth.mask.shape, dtype=bool)
    saturated[40:44, 50:60] = True  # 40 pixels at the white level
    plain = _observe(photo, truth, light)
    s = _observe(photo, truth, light, saturated=saturated)
    assert s.removed["saturated"] == 40 and plain.removed["saturated"] == 0
    assert len(s) == len(plain) - 40
    kept = {tuple(px) for px in s.pixel}
    assert not any((r, c) in kept for r in range(40, 44) for c in range(50, 60))
    # with a clip level too, a pixel is saturated by either rule, counted once
    photo[40, 50] = photo[10, 10] = 50.0
    both = _observe(photo, truth, light, saturated=saturated,
                    settings=observations.ObservationSettings(clip_level=10.0))
    assert both.removed["saturated"] == 41
    with pytest.raises(ValueError, match="saturated must have shape"):
        _observe(photo, truth, light, saturated=saturated[:-1])


# --------------------------------------------------------------------- extremes
def test_extreme_all_saturated_photo(scene):
    truth, _ = scene
    photo = np.full(truth.mask.shape + (3,), 100.0)
    s = _observe(photo, truth, synthetic.LIGHTS[3],
                 settings=observations.ObservationSettings(clip_level=1.0))
    assert len(s) == 0 and s.removed["saturated"] > 0
    with pytest.raises(ValueError, match="no samples"):
        reliable.reliable_candidates(s)


def test_extreme_light_exactly_at_grazing(scene):
    truth, _ = scene
    light = np.array([1.0, 0.0, 0.0])  # in the plane of a flat surface
    photo = synthetic.photo(_lambert_table(), truth, light)
    s = _observe(photo, truth, light)
    assert np.all(np.sum(s.n * s.l, axis=1) >= 0.1)  # grazing ones removed
    assert s.removed["grazing"] > 0
    assert np.all(np.isfinite(s.rho))


def test_extreme_camera_at_the_light(scene):
    """h = v = l: every sample in phi_d bin 0 ... theta_d = 0, finite rho."""
    truth, _ = scene
    light = np.array([0.0, 0.0, 1.0])  # the orthographic camera looks down -z
    photo = synthetic.photo(_lambert_table(0.3), truth, light)
    s = _observe(photo, truth, light)
    assert np.all(s.cells[:, 1] == 0)  # theta_d = 0
    np.testing.assert_allclose(s.rho, 0.3 / np.pi, rtol=1e-9)
    cand, _ = reliable.reliable_candidates(s)
    assert np.all(np.isfinite(cand.rho))


def test_extreme_nan_in_normals(scene):
    truth, _ = scene
    light = synthetic.LIGHTS[0]
    photo = synthetic.photo(_lambert_table(), truth, light)
    normal = truth.normal.copy()
    normal[40:42, 40:42] = np.nan
    g = synthetic.GBuffer(normal, truth.position, truth.mask, truth.camera_center)
    s = _observe(photo, g, light)
    assert s.removed["nonfinite"] == 4
    assert np.all(np.isfinite(s.n)) and np.all(np.isfinite(s.rho))
    cand, _ = reliable.reliable_candidates(s)
    assert np.all(np.isfinite(cand.rho))


# ------------------------------------------------------- the curvature map, views
def test_curvature_map_reuse_gives_identical_samples(scene):
    """Photos from one camera share G-buffers; their curvature is computed once."""
    truth, scan = scene
    light = synthetic.LIGHTS[1]
    photo = synthetic.photo(_lambert_table(), truth, light)
    H = observations.image_curvature(scan.normal, scan.position, scan.mask)
    a = _observe(photo, scan, light)
    b = _observe(photo, scan, light, curvature_map=H)
    np.testing.assert_array_equal(a.curvature, b.curvature)
    np.testing.assert_array_equal(a.rho, b.rho)


def test_observe_view_directions_and_subset_match_the_plain_ones(scene):
    import dataclasses

    from brdf_reconstruct.core.brdf import render

    truth, scan = scene
    light = synthetic.LIGHTS[2]
    camera = np.array([0.3, -0.2, 4.0])  # perspective: view directions vary
    photo = synthetic.photo(_lambert_table(), truth, light)
    s = observations.observe(photo, scan.normal, scan.position, np.ones(scan.mask.shape),
                             np.zeros(scan.mask.shape, dtype=int), camera, light)
    p = scan.position[s.pixel[:, 0], s.pixel[:, 1]]
    np.testing.assert_array_equal(s.v, render.view_directions(camera, p))
    n = scan.normal[s.pixel[:, 0], s.pixel[:, 1]]
    np.testing.assert_array_equal(s.n, n / np.linalg.norm(n, axis=1, keepdims=True))
    keep = np.random.default_rng(0).random(len(s)) < 0.5
    for index in (keep, np.flatnonzero(keep), np.flatnonzero(keep)[::-1], [], [-1, 0]):
        sub = s.subset(index)
        for f in dataclasses.fields(s):
            if f.name not in ("shapes", "removed"):
                np.testing.assert_array_equal(getattr(sub, f.name), getattr(s, f.name)[index])


def test_a_pixel_footprint_follows_its_samples_and_is_checked():
    """observe keeps footprint_normal's points of each kept pixel, normalised;
    subset and concatenate carry them; a wrong shape, or photos with and without
    a footprint together, are refused with one sentence."""

    z = synthetic.height_field(16)
    g = synthetic.gbuffer_from_heights(z)
    photo = np.ones((16, 16, 3))
    foot = np.repeat(2.0 * g.normal[:, :, None, :], 4, axis=2)  # (16, 16, 4, 3), length 2
    foot[0, 0, 1] = np.nan  # a point off the object
    args = (photo, g.normal, g.position, np.ones((16, 16)), np.zeros((16, 16), int),
            g.camera_center, synthetic.LIGHTS[0])
    s = observations.observe(*args, footprint_normal=foot)
    assert s.footprint.shape == (len(s), 4, 3)
    rows = s.pixel[:, 0] * 16 + s.pixel[:, 1]
    expect = g.normal.reshape(-1, 3)[rows] / np.linalg.norm(g.normal.reshape(-1, 3)[rows],
                                                            axis=1, keepdims=True)
    finite = np.isfinite(s.footprint).all(axis=2)
    np.testing.assert_allclose(s.footprint[finite], np.repeat(expect[:, None], 4, 1)[finite])
    assert (~finite).sum() == (1 if 0 in rows else 0)
    part = s.subset(np.arange(len(s)) % 3 == 0)
    np.testing.assert_array_equal(part.footprint, s.footprint[::3])
    both = observations.concatenate([s, part])
    assert both.footprint.shape == (len(s) + len(part), 4, 3)
    plain = observations.observe(*args)
    assert plain.footprint.shape == (len(plain), 0, 3)
    assert plain.subset([0, 1]).footprint.shape == (2, 0, 3)
    with pytest.raises(ValueError, match="same footprint points"):
        observations.concatenate([s, plain])
    with pytest.raises(ValueError, match="footprint_normal must have shape"):
        observations.observe(*args, footprint_normal=foot[:, :, 0])
