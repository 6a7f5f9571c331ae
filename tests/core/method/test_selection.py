"""G-buffer shading and KL selection of candidate BRDFs (paper Sec. 3.2)."""

import dataclasses

import numpy as np
import pytest

from brdf_reconstruct.core.brdf import database, merl, render
from brdf_reconstruct.core.method import selection
from brdf_reconstruct.core.method.selection import (
    SelectionResult,
    View,
    photo_range,
    select_by_kl,
    shade_gbuffer,
)

CAMERA = np.array([0.0, 0.0, 4.0])
LIGHTS = (np.array([0.3, 0.4, 1.0]), np.array([-0.6, 0.1, 0.8]))
IRRADIANCE = np.array([2.0, 1.5, 1.0])


def sphere_gbuffer(resolution=64, radius=1.0, camera=CAMERA, tan_half_fov=0.3):
    """Ray-cast a sphere at the origin from a pinhole camera at ``camera`` looking down -z.

    Returns normal (H, W, 3), position (H, W, 3), mask (H, W) bool, world space.
    """
    c = ((np.arange(resolution) + 0.5) / resolution * 2.0 - 1.0) * tan_half_fov
    x, y = np.meshgrid(c, -c)
    d = np.stack([x, y, -np.ones_like(x)], axis=-1)
    d /= np.linalg.norm(d, axis=-1, keepdims=True)
    # |o + t d|^2 = r^2  ->  t^2 + 2 (o.d) t + |o|^2 - r^2 = 0, nearer root
    b = d @ camera
    disc = b**2 - (camera @ camera - radius**2)
    mask = disc > 0.0
    t = -b - np.sqrt(np.clip(disc, 0.0, None))
    position = np.where(mask[..., None], camera + t[..., None] * d, 0.0)
    normal = position / radius
    return normal, position, mask


@pytest.fixture(scope="module")
def gbuffer():
    return sphere_gbuffer()


@pytest.fixture(scope="module")
def tables():
    """Ground truth and a different material, each built once (about 0.6 s each).

    "truth" keeps the NaN cells of an analytic table (below the horizon);
    "truth_filled" has them filled once, which spares the lookups the filling.
    """
    specs = {s["name"]: s for s in database.heldout_specs()}
    truth = database.make_table(specs["heldout_glossy_plastic"])
    return {
        "truth": truth,
        "truth_filled": merl.fill_unmeasured(truth),
        "other": database.make_table(specs["heldout_rough_plastic"]),
    }


def make_views(table, gbuffer, lights=LIGHTS):
    normal, position, mask = gbuffer
    visibility = np.ones(mask.shape)
    views = []
    for light in lights:
        photo = shade_gbuffer(table, normal, visibility, mask, position, CAMERA, light, IRRADIANCE)
        views.append(View(photo, normal, visibility, mask, position, CAMERA, light, IRRADIANCE))
    return views


def lambert_table(albedo):
    """Constant table rho = albedo / pi (RGB), 1/sr."""
    return np.broadcast_to(
        (np.asarray(albedo, dtype=np.float64) / np.pi)[:, None, None, None], (3, *merl.SHAPE)
    )


# ------------------------------------------------------------------------- shading
def test_lambertian_matches_analytic(gbuffer):
    normal, position, mask = gbuffer
    albedo = np.array([0.8, 0.5, 0.2])
    light = LIGHTS[0] / np.linalg.norm(LIGHTS[0])
    image = shade_gbuffer(
        lambert_table(albedo), normal, np.ones(mask.shape), mask, position, CAMERA,
        LIGHTS[0], IRRADIANCE,
    )
    expected = albedo / np.pi * np.clip(normal @ light, 0.0, None)[..., None] * IRRADIANCE
    np.testing.assert_allclose(image[mask], expected[mask], rtol=1e-12, atol=1e-15)
    assert np.all(image[~mask] == 0.0)
    assert np.count_nonzero(image[mask].sum(axis=1) > 0) > mask.sum() // 3  # lit part


def test_scalar_irradiance_and_unnormalised_light(gbuffer):
    normal, position, mask = gbuffer
    table = lambert_table([0.5, 0.5, 0.5])
    vis = np.ones(mask.shape)
    a = shade_gbuffer(table, normal, vis, mask, position, CAMERA, LIGHTS[1], 3.0)
    b = shade_gbuffer(table, normal, vis, mask, position, CAMERA, 7.0 * LIGHTS[1], [3.0] * 3)
    np.testing.assert_allclose(a, b, rtol=1e-12, atol=1e-300)


def test_matches_render_shade_with_per_pixel_view(tables, gbuffer):
    normal, position, mask = gbuffer
    image = shade_gbuffer(
        tables["truth"], normal, np.ones(mask.shape), mask, position, CAMERA, LIGHTS[0], 1.0
    )
    v = CAMERA - position[mask]
    v /= np.linalg.norm(v, axis=1, keepdims=True)
    light = LIGHTS[0] / np.linalg.norm(LIGHTS[0])
    np.testing.assert_allclose(
        image[mask], render.shade(tables["truth_filled"], normal[mask], light, v), rtol=1e-12
    )


def test_visibility_scales_radiance_and_zero_is_black(gbuffer):
    normal, position, mask = gbuffer
    table = lambert_table([0.6, 0.6, 0.6])
    full = shade_gbuffer(table, normal, np.ones(mask.shape), mask, position, CAMERA, LIGHTS[0])
    vis = np.ones(mask.shape)
    vis[:, :32] = 0.0
    vis[:32, 32:] = 0.5
    shaded = shade_gbuffer(table, normal, vis, mask, position, CAMERA, LIGHTS[0])
    assert np.all(shaded[:, :32] == 0.0)
    assert full[:, :32].max() > 0.0  # those pixels were lit before
    np.testing.assert_allclose(shaded[:32, 32:], 0.5 * full[:32, 32:], rtol=1e-12)
    np.testing.assert_array_equal(shaded[32:, 32:], full[32:, 32:])


def test_float32_gbuffers(gbuffer):
    normal, position, mask = gbuffer
    table = lambert_table([0.3, 0.4, 0.5])
    vis = np.ones(mask.shape)
    a = shade_gbuffer(table, normal, vis, mask, position, CAMERA, LIGHTS[0])
    b = shade_gbuffer(
        table, normal.astype(np.float32), vis.astype(np.float32), mask,
        position.astype(np.float32), CAMERA.astype(np.float32), LIGHTS[0].astype(np.float32),
    )
    assert b.dtype == np.float64
    np.testing.assert_allclose(a, b, rtol=1e-5, atol=1e-9)


def test_empty_mask_renders_black(gbuffer):
    normal, position, mask = gbuffer
    image = shade_gbuffer(
        lambert_table([1, 1, 1]), normal, np.ones(mask.shape), np.zeros_like(mask), position,
        CAMERA, LIGHTS[0],
    )
    assert image.shape == (*mask.shape, 3) and not image.any()


@pytest.mark.parametrize(
    "change, message",
    [
        ({"normal": np.zeros((64, 64, 2))}, "normal must have shape"),
        ({"visibility": np.full((64, 64), 1.5)}, r"visibility must lie in \[0, 1\]"),
        ({"mask": np.ones((64, 64), dtype=np.int64)}, "mask must be a bool"),
        ({"light": np.zeros(3)}, "light must be"),
        ({"camera_center": np.array([0.0, np.nan, 1.0])}, "camera_center"),
        ({"irradiance": -1.0}, "irradiance"),
        ({"irradiance": np.ones(4)}, "irradiance"),
    ],
)
def test_shade_gbuffer_bad_input(gbuffer, change, message):
    normal, position, mask = gbuffer
    args = {
        "normal": normal, "visibility": np.ones(mask.shape), "mask": mask,
        "position": position, "camera_center": CAMERA, "light": LIGHTS[0], "irradiance": 1.0,
    }
    args.update(change)
    with pytest.raises(ValueError, match=message):
        shade_gbuffer(lambert_table([1, 1, 1]), **args)


# ----------------------------------------------------------------------- selection
def test_picks_the_ground_truth(tables, gbuffer):
    truth = tables["truth"]  # with NaN cells: select_by_kl fills them
    views = make_views(tables["truth_filled"], gbuffer)
    candidates = [0.5 * truth, tables["other"], truth, 2.0 * truth]
    result = select_by_kl(candidates, views)
    assert isinstance(result, SelectionResult)
    assert result.winner == 2
    assert result.kl.shape == (4,) and result.kl_per_view.shape == (4, 2)
    assert result.kl[2] == pytest.approx(0.0, abs=1e-12)
    others = np.delete(result.kl, 2)
    assert np.all(others > 0.1), result.kl
    np.testing.assert_allclose(result.kl, result.kl_per_view.mean(axis=1))
    np.testing.assert_array_equal(result.excluded, [0, 0])
    np.testing.assert_array_equal(result.n_pixels, [gbuffer[2].sum()] * 2)
    assert result.renders is None


def test_sum_aggregate_same_winner(tables, gbuffer):
    truth = tables["truth_filled"]
    views = make_views(truth, gbuffer)
    candidates = [truth, 2.0 * truth]
    mean = select_by_kl(candidates, views)
    total = select_by_kl(candidates, views, aggregate="sum")
    assert mean.winner == total.winner == 0
    np.testing.assert_allclose(total.kl, 2.0 * mean.kl)


def test_nan_photo_pixels_are_excluded_and_counted(tables, gbuffer):
    truth = tables["truth_filled"]
    views = make_views(truth, gbuffer)
    photo = views[0].photo.copy()
    rows, cols = np.nonzero(views[0].mask)
    photo[rows[:37], cols[:37], 1] = np.nan
    photo[rows[-5:], cols[-5:]] = np.inf
    photo[0, 0] = np.nan  # outside the mask (corner of the image): not counted
    assert not views[0].mask[0, 0]
    views[0] = dataclasses.replace(views[0], photo=photo)
    result = select_by_kl([2.0 * truth, truth], views)
    np.testing.assert_array_equal(result.excluded, [42, 0])
    np.testing.assert_array_equal(result.n_pixels, [gbuffer[2].sum() - 42, gbuffer[2].sum()])
    assert result.winner == 1
    assert result.kl[1] == pytest.approx(0.0, abs=1e-12)
    assert np.all(np.isfinite(result.kl))


def test_photo_range_stops_at_the_cameras_dynamic_range():
    pixels = np.array([[1e-301, 0.0, 2.0], [-1.0, 0.5, 4.0]])
    assert photo_range(pixels) == (selection.DYNAMIC_RANGE * 4.0, 4.0)
    assert photo_range(np.array([0.25, 0.5])) == (0.25, 0.5)  # within the range: as it is
    lo, hi = photo_range(np.array([3.0, 3.0]))
    assert lo == pytest.approx(3.0 * np.exp(-0.5)) and hi == pytest.approx(3.0 * np.exp(0.5))
    assert photo_range(np.array([0.0, -2.0])) is None


def test_values_darker_than_the_cameras_range_do_not_move_the_scores(tables, gbuffer,
                                                                      monkeypatch):
    # A synthetic photo's shadows can hold values down to 1e-301. Whether they are
    # that, a 1e-7 relative perturbation of that, or exactly zero, no camera would
    # tell them apart: the scores must be the same to the last bit.
    truth = tables["truth_filled"]
    views = make_views(truth, gbuffer)
    rows, cols = np.nonzero(views[0].mask)
    dark = (rows[::3], cols[::3])  # a third of the object
    brightest = views[0].photo[views[0].mask].max()
    rng = np.random.default_rng(0)
    tiny = brightest * 10.0 ** rng.uniform(-301.0, -7.0, (dark[0].size, 1)) * np.ones(3)
    candidates = [truth, 0.5 * truth, tables["other"]]

    def scores(values):
        photo = views[0].photo.copy()
        photo[dark] = values
        return select_by_kl(candidates, [dataclasses.replace(views[0], photo=photo),
                                         views[1]]).kl

    as_given = scores(tiny)
    np.testing.assert_array_equal(as_given, scores(tiny * (1.0 + 1e-7 * rng.standard_normal(
        tiny.shape))))
    np.testing.assert_array_equal(as_given, scores(0.0))
    assert np.all(np.isfinite(as_given))
    # Bins spread down to the darkest value (the old policy) make those values count.
    monkeypatch.setattr(selection, "DYNAMIC_RANGE", 0.0)
    assert not np.array_equal(scores(tiny), scores(0.0))


def test_mapping_views_and_kept_renders(gbuffer):
    normal, position, mask = gbuffer
    truth = lambert_table([0.5, 0.4, 0.3])
    views = [dataclasses.asdict(v) for v in make_views(truth, gbuffer)]
    del views[1]["irradiance"]  # defaults to 1
    result = select_by_kl([truth, 0.3 * truth], views, keep_renders=True)
    assert len(result.renders) == 2 and len(result.renders[0]) == 2
    np.testing.assert_array_equal(result.renders[0][0], views[0]["photo"])
    np.testing.assert_array_equal(
        result.renders[1][1],
        shade_gbuffer(0.3 * truth, normal, np.ones(mask.shape), mask, position, CAMERA,
                      LIGHTS[1]),
    )
    assert result.kl_per_view[0, 0] == 0.0 and result.kl_per_view[0, 1] > 0.0


def test_per_channel_mode(gbuffer):
    grey = lambert_table([0.4, 0.4, 0.4])
    # Same luminance as the grey material, different colour.
    w = np.array([0.2126, 0.7152, 0.0722])
    tint = np.array([0.8, 0.3, 0.4])
    tinted = lambert_table(tint * 0.4 / (tint @ w))
    views = make_views(grey, gbuffer)
    per_channel = select_by_kl([tinted, grey], views, mode="per_channel")
    assert per_channel.winner == 1 and per_channel.kl[0] > 1.0


@pytest.mark.parametrize(
    "make, message",
    [
        (lambda t, v: ([], v), "tables is empty"),
        (lambda t, v: ([t], []), "views is empty"),
        (lambda t, v: ([t[:, :45]], v), r"tables\[0\] must have shape"),
        (lambda t, v: ([t], [{"photo": v[0].photo}]), r"views\[0\] lacks"),
        (lambda t, v: ([t], [v[0], dataclasses.replace(v[1], photo=np.full_like(v[1].photo,
                                                                                 np.nan))]),
         r"views\[1\] has no usable pixel"),
        (lambda t, v: ([t], [dataclasses.replace(v[0], photo=v[0].photo[:10])]),
         r"views\[0\]\.photo must have shape"),
        (lambda t, v: ([t], v, {"aggregate": "max"}), "aggregate"),
    ],
)
def test_select_bad_input(gbuffer, make, message):
    table = lambert_table([0.5, 0.5, 0.5])
    views = make_views(table, gbuffer)
    args = make(np.ascontiguousarray(table), views)
    kwargs = args[2] if len(args) == 3 else {}
    with pytest.raises(ValueError, match=message):
        select_by_kl(args[0], args[1], **kwargs)


def test_reconstructions_are_scored_at_the_photos_cells_like_their_tables(
        default_basis, heldout_tables):
    """Candidates given as reconstructions are read only at the cells the views need;
    the KL scores equal those of their expanded tables, and the winner is the same."""
    from brdf_reconstruct.core.method import reconstruct, sampling

    B = default_basis
    truth = heldout_tables["heldout_glossy_plastic"]
    views = make_views(truth, sphere_gbuffer(48))
    cand = merl.cells_from_linear(B.cells)
    recs = []
    for n, seed in ((6, 0), (20, 1), (40, 2)):
        cells = sampling.optimal_cells(B, cand, n, seed)
        recs.append(reconstruct.reconstruct(
            B, cells, truth.reshape(3, -1)[:, merl.linear_index(cells)].T))
    lazy = select_by_kl(recs, views)
    assert "table" not in vars(recs[0])  # no full table was expanded for the scores
    full = select_by_kl([r.expand() for r in recs], views)
    np.testing.assert_allclose(lazy.kl, full.kl, rtol=1e-9)
    assert lazy.winner == full.winner


# ------------------------------------------------------------- the photos' check
def test_rmse_is_the_renders_relative_rmse_against_the_photos(tables, gbuffer):
    """SelectionResult.rmse from the kept renders, recomputed here."""
    views = make_views(tables["truth_filled"], gbuffer)
    candidates = [tables["truth_filled"], 1.5 * tables["truth_filled"], tables["other"]]
    result = select_by_kl(candidates, views, keep_renders=True)
    mask = gbuffer[2]
    photo_sq = sum(np.sum(v.photo[mask] ** 2) for v in views)
    for t in range(3):
        miss = sum(np.sum((result.renders[t][i][mask] - v.photo[mask]) ** 2)
                   for i, v in enumerate(views))
        assert result.rmse[t] == pytest.approx(np.sqrt(miss / photo_sq), rel=1e-12)
    assert result.rmse[0] == pytest.approx(0.0, abs=1e-12)
    assert result.rmse[1] == pytest.approx(0.5, rel=1e-9)  # 1.5 x the photos everywhere


def test_a_spike_far_above_the_photos_is_not_chosen_by_its_kl(tables, gbuffer):
    """Against a table 30 % too bright, the truth with its peak 1e4 times higher
    (theta_h bins 0 to 7, below 0.8 degrees): the spike moves a few pixels between
    the histograms' bins (KL 0.002 against 0.43), so the KL prefers it, but it
    misses the photos thousands of times more; the photos' check
    (selection.photo_eligible) leaves the KL the 30 % table."""
    truth = tables["truth_filled"]
    views = make_views(truth, gbuffer)
    spiked = truth.copy()
    spiked[:, :8] *= 1e4
    result = select_by_kl([1.3 * truth, spiked], views)
    assert result.kl[1] < result.kl[0] and result.winner == 1  # the KL alone is fooled
    assert result.rmse[0] == pytest.approx(0.3, rel=1e-9)
    assert result.rmse[1] > selection.MAX_RMSE_RATIO * result.rmse[0]
    eligible = selection.photo_eligible(result.rmse)
    np.testing.assert_array_equal(eligible, [True, False])
    assert selection.eligible_winner(result.kl, eligible) == 0


def test_photo_eligible_reads_the_ratio_to_the_best_and_never_excludes_all():
    rmse = [1.0, 4.9, 5.1, np.nan, np.inf]
    np.testing.assert_array_equal(selection.photo_eligible(rmse), [1, 1, 0, 1, 0])
    np.testing.assert_array_equal(selection.photo_eligible(rmse, ratio=6.0), [1, 1, 1, 1, 0])
    assert selection.photo_eligible([np.nan, np.inf]).all()  # nothing to judge by
    kl = [0.5, 0.4, 0.1, 0.6, 0.05]
    assert selection.eligible_winner(kl, selection.photo_eligible(rmse)) == 1
    assert selection.eligible_winner(kl, [False] * 5) == 4  # none eligible: the KL's
