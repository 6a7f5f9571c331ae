"""The reliable region (core.method.reliable) on numpy scenes with known answers:
the curvature, monotonicity and brightest-peak stages, the seeded trials, the fast
paths against plain references, and the checks of the paper's assumptions before
applying them (ReliableSettings ``peak_max_angle`` and ``monotonicity_max_fraction``)."""

import numpy as np
import pytest
from observing import lambert_table as _lambert_table
from observing import observe as _observe

from brdf_reconstruct.core.brdf import database
from brdf_reconstruct.core.method import observations, reliable
from testkit import synthetic


# ------------------------------------------------------------------------ extremes
def test_extreme_single_pixel_region(scene):
    truth, _ = scene
    light = synthetic.LIGHTS[3]
    photo = synthetic.photo(_lambert_table(), truth, light)
    region = np.zeros(truth.mask.shape, dtype=int)
    region[50, 50] = 7
    s = _observe(photo, truth, light, region=region)
    cand, report = reliable.reliable_candidates(
        s, reliable.ReliableSettings(use_curvature=False))
    assert 7 in cand.region  # its own peak, never removed
    assert len(report.peaks) == 2


def test_no_reliable_pixels_is_a_clear_error(scene):
    _, scan = scene
    light = synthetic.LIGHTS[0]
    photo = synthetic.photo(_lambert_table(), scan, light)
    s = _observe(photo, scan, light)
    with pytest.raises(ValueError, match="no reliable pixels left after the curvature"):
        reliable.reliable_candidates(s, reliable.ReliableSettings(
            curvature_threshold=-1.0, use_brightest=False))


# --------------------------------------------------------------------- reliable region
def test_curvature_stage_keeps_better_normals(scene):
    truth, scan = scene
    light = synthetic.LIGHTS[0]
    photo = synthetic.photo(_lambert_table(), truth, light)
    s = _observe(photo, scan, light)
    cand, report = reliable.reliable_candidates(s, reliable.ReliableSettings(
        use_monotonicity=False, use_brightest=False))
    assert report.removed["curvature"] > 0
    angle = synthetic.normal_angle_error(truth, scan)
    kept = angle[cand.pixel[:, 0], cand.pixel[:, 1]]
    everything = angle[s.pixel[:, 0], s.pixel[:, 1]]
    assert np.median(kept) < 0.5 * np.percentile(everything, 90)
    assert np.mean(kept) < np.mean(everything)


def test_monotonicity_does_not_gut_a_lambertian_region(scene):
    truth, scan = scene
    parts = []
    for i, light in enumerate(synthetic.LIGHTS):
        photo = synthetic.photo(_lambert_table(0.5), truth, light, noise=0.02, rng=i)
        parts.append(_observe(photo, scan, light, view_index=i))
    s = observations.concatenate(parts)
    cand, report = reliable.reliable_candidates(s, reliable.ReliableSettings(
        use_curvature=False, use_brightest=False))
    # blunted normals scatter rho (cosine divided by the wrong n.l), yet most survive
    assert report.removed["monotonicity"] < 0.25 * len(s)
    # with exact normals, rho is flat: nothing but noise, nothing removed
    exact = observations.concatenate([
        _observe(synthetic.photo(_lambert_table(0.5), truth, light, noise=0.02, rng=i),
                 truth, light, view_index=i) for i, light in enumerate(synthetic.LIGHTS)])
    _, exact_report = reliable.reliable_candidates(exact, reliable.ReliableSettings(
        use_curvature=False, use_brightest=False))
    assert exact_report.removed["monotonicity"] == 0


def test_monotonicity_removes_samples_with_wrong_normals():
    """rho = f(n.h) increasing; a few samples given a wrong (lower) n.h look too bright
    for their n.h and must go, the rest must stay."""
    rng = np.random.default_rng(0)
    N = 2000
    ndoth = rng.uniform(0.5, 1.0, N)
    rho = np.exp(8.0 * (ndoth - 1.0))[:, None].repeat(3, axis=1)
    wrong = rng.choice(N, 40, replace=False)
    shown = ndoth.copy()
    shown[wrong] = np.clip(shown[wrong] - 0.3, 0.5, None)
    # directions with n.h = shown: n = z, h tilted by acos(shown) about y, l = v = h
    theta = np.arccos(shown)
    h = np.stack([np.sin(theta), np.zeros(N), np.cos(theta)], axis=1)
    s = observations.Samples(
        n=np.tile([0.0, 0.0, 1.0], (N, 1)), l=h, v=h, rho=rho, radiance=rho,
        irradiance=np.ones((N, 3)), cells=np.zeros((N, 3), dtype=np.int64),
        view=np.zeros(N, dtype=np.int64), pixel=np.zeros((N, 2), dtype=np.int64),
        region=np.zeros(N, dtype=np.int64), curvature=np.zeros(N), shapes=((1, 1),))
    resid = reliable.monotone_residuals(s)
    flagged = np.flatnonzero(np.any(resid > np.log(2.0), axis=1))  # off by a factor 2
    assert len(np.intersect1d(flagged, wrong)) >= 30  # most wrong normals caught
    assert len(np.setdiff1d(flagged, wrong)) < 0.02 * N  # few good samples lost


def test_brightest_peak_ignores_a_single_hot_pixel(scene):
    truth, _ = scene
    light = synthetic.LIGHTS[0] / np.linalg.norm(synthetic.LIGHTS[0])
    spec = {"name": "gloss", "lobes": [{"type": "lambert", "albedo": 0.2}],
            "coat": {"distribution": "ggx", "alpha": 0.1, "eta": 1.5}}
    from brdf_reconstruct.core.brdf import database

    photo = synthetic.photo(database.make_table(spec), truth, light)
    hot = (5, 5)
    photo[hot] = 100.0 * photo.max()
    s = _observe(photo, truth, light)
    (peak,) = reliable.brightest_peaks(s)
    assert tuple(s.pixel[peak]) != hot
    # the peak sits where the true normal is closest to h = normalize(l + v)
    h = light + np.array([0.0, 0.0, 1.0])
    h /= np.linalg.norm(h)
    ndoth = truth.normal @ h
    assert ndoth[tuple(s.pixel[peak])] >= np.percentile(ndoth, 99.5)
    cand, report = reliable.reliable_candidates(s)
    k = report.peaks[0]
    h_own = (cand.l[k] + cand.v[k]) / np.linalg.norm(cand.l[k] + cand.v[k])
    np.testing.assert_allclose(cand.n[k], h_own, atol=1e-12)  # Eq. (2): n := h
    assert cand.cells[k, 0] == 0  # lands in theta_h = 0


def test_trials_are_seeded(default_basis, scene):
    truth, scan = scene
    light = synthetic.LIGHTS[0]
    photo = synthetic.photo(_lambert_table(0.3), truth, light)
    s = _observe(photo, scan, light)
    cand, report = reliable.reliable_candidates(s)
    a = reliable.trial_candidates(default_basis, cand, 6, 3, 42, peaks=report.peaks)
    b = reliable.trial_candidates(default_basis, cand, 6, 3, 42, peaks=report.peaks)
    assert len(a) == 3
    for (ra, ua), (rb, ub) in zip(a, b, strict=True):
        np.testing.assert_array_equal(ua, ub)
        np.testing.assert_array_equal(ra.table, rb.table)
        assert np.all(np.isin(report.peaks, ua))
    assert not np.array_equal(a[0][1], a[1][1])  # trials differ


# ------------------------------------------------- fast paths against plain references
def _bare_samples(rng, shapes, fill, n_regions, radiance=None):
    """Samples on random pixels of views of ``shapes`` (random order), random regions."""
    view, pixel = [], []
    for v, shape in enumerate(shapes):
        r, c = np.nonzero(rng.random(shape) < fill)
        view.append(np.full(len(r), v))
        pixel.append(np.stack([r, c], axis=1))
    view, pixel = np.concatenate(view), np.concatenate(pixel)
    perm = rng.permutation(len(view))
    N = len(view)
    z = np.zeros((N, 3))
    if radiance is None:
        radiance = rng.integers(0, 4, (N, 3)) / 4.0  # many ties in luminance
    return observations.Samples(
        n=z, l=z, v=z, rho=z, radiance=radiance, irradiance=z,
        cells=np.zeros((N, 3), dtype=np.int64), view=view[perm].astype(np.int64),
        pixel=pixel[perm].astype(np.int64),
        region=rng.integers(0, n_regions, N).astype(np.int64), curvature=np.zeros(N),
        shapes=tuple(shapes))


def _peaks_reference(s):
    score = reliable.brightness(s)
    return np.array([np.flatnonzero(s.region == r)[np.argmax(score[s.region == r])]
                     for r in np.unique(s.region)], dtype=np.int64)


def test_brightest_peaks_equals_the_argmax_of_brightness():
    """Median only where it can win: the same peaks (first among ties) as the arg-max
    of the full 3 x 3 median brightness, with ties, several views and regions, hot
    pixels, and the inputs that take the plain path (two samples on one pixel,
    a non-finite luminance, negative regions)."""
    import dataclasses

    rng = np.random.default_rng(5)
    for trial in range(300):
        shapes = [tuple(rng.integers(1, 30, 2)) for _ in range(rng.integers(1, 4))]
        s = _bare_samples(rng, shapes, rng.uniform(0.1, 1.0), int(rng.integers(1, 5)))
        if len(s) == 0:
            continue
        if trial % 3 == 0:
            s.radiance[rng.integers(len(s))] = 50.0  # hot pixel
        if trial % 7 == 0:
            s = dataclasses.replace(s, region=s.region - 2)
        got = reliable.brightest_peaks(s)
        assert got.dtype == np.int64
        np.testing.assert_array_equal(got, _peaks_reference(s))
    s = _bare_samples(rng, [(20, 20)], 0.8, 2)
    twice = s.subset(np.r_[np.arange(len(s)), 0])  # sample 0's pixel twice
    np.testing.assert_array_equal(reliable.brightest_peaks(twice), _peaks_reference(twice))
    s.radiance[3] = np.nan
    np.testing.assert_array_equal(reliable.brightest_peaks(s), _peaks_reference(s))


def test_monotone_residuals_equal_a_plain_sort_and_fit():
    """The radix-sorted, vectorised residuals equal a per-region argsort + fit, bit
    for bit: ties in n.h (stable order), several and negative regions, NaN n.h."""
    import dataclasses

    from scipy.optimize import isotonic_regression


    def reference(s):
        h = s.l + s.v
        h /= np.linalg.norm(h, axis=1, keepdims=True)
        ndoth = np.sum(s.n * h, axis=1)
        out = np.zeros_like(s.rho)
        for region in np.unique(s.region):
            sel = np.flatnonzero(s.region == region)
            order = sel[np.argsort(ndoth[sel], kind="stable")]
            for c in range(3):
                rho = s.rho[order, c]
                delta = 1e-3 * max(float(np.median(rho)), 1e-12)
                y = np.log(np.maximum(rho, 0.0) + delta)
                out[order, c] = np.abs(y - isotonic_regression(y, increasing=True).x)
        return out

    rng = np.random.default_rng(6)
    for trial in range(60):
        N = int(rng.integers(1, 400))
        n = rng.normal(size=(N, 3))
        if trial % 2:
            n = np.round(n * 2) / 2  # many equal n.h
        n[:, 2] = np.abs(n[:, 2]) + 0.1
        l = np.tile([0.0, 0.0, 1.0], (N, 1)) if trial % 2 else rng.normal(size=(N, 3))  # noqa: E741
        v = l.copy() if trial % 2 else rng.normal(size=(N, 3))
        if trial % 5 == 0:
            v[0] = -l[0]  # h = 0: n.h is NaN
        rho = rng.random((N, 3)) ** 3
        rho[rng.random((N, 3)) < 0.05] = 0.0
        s = _bare_samples(rng, [(1, 1)], 1.0, 1)
        s = dataclasses.replace(
            s, n=n, l=l, v=v, rho=rho, radiance=rho, irradiance=rho,
            cells=np.zeros((N, 3), dtype=np.int64), view=np.zeros(N, dtype=np.int64),
            pixel=np.zeros((N, 2), dtype=np.int64), curvature=np.zeros(N),
            region=rng.integers(-2, 3, N) if trial % 3 else rng.integers(0, 4, N))
        with np.errstate(invalid="ignore"):
            np.testing.assert_array_equal(reliable.monotone_residuals(s), reference(s))


# ---------------------------------------------- the checks of the paper's assumptions
def _samples(table, scene, lights=synthetic.LIGHTS[:3]):
    truth, scan = scene
    parts = []
    for i, light in enumerate(lights):
        photo = synthetic.photo(table, truth, light)
        parts.append(observations.observe(
            photo, scan.normal, scan.position, np.ones(scan.mask.shape),
            np.zeros(scan.mask.shape, dtype=int), scan.camera_center, light, view_index=i))
    return observations.concatenate(parts)


def _spec(name):
    return next(s for s in database.heldout_specs() if s["name"] == name)


def test_sheen_brightest_pixel_is_not_taken_as_a_specular_peak(scene):
    # cloth is brightest towards grazing, 44 deg from h here: Eq. 2 must not fire
    s = _samples(database.make_table(_spec("heldout_fabric")), scene)
    cand, report = reliable.reliable_candidates(s)
    assert report.skipped.get("brightest") == [0]
    assert len(report.peaks) == 0
    _, literal = reliable.reliable_candidates(
        s, reliable.ReliableSettings(peak_max_angle=np.pi))
    assert len(literal.peaks) == 1  # the paper's literal rule would have moved it


def test_glossy_peak_is_still_corrected(scene):
    s = _samples(database.make_table(_spec("heldout_gold_medium")), scene)
    cand, report = reliable.reliable_candidates(s)
    assert "brightest" not in report.skipped and len(report.peaks) == 1
    k = report.peaks[0]
    h = cand.l[k] + cand.v[k]
    np.testing.assert_allclose(cand.n[k], h / np.linalg.norm(h), atol=1e-12)


def test_monotonicity_is_skipped_where_the_data_reject_it(scene):
    # sheen: reflectance rises towards grazing, i.e. falls as n.h grows (Eq. 1 fails)
    s = _samples(database.make_table(_spec("heldout_random_fabric")), scene)
    strict = reliable.ReliableSettings(monotonicity_max_fraction=1.0, use_curvature=False)
    _, applied = reliable.reliable_candidates(s, strict)
    fraction = applied.removed["monotonicity"] / applied.input
    guarded = reliable.ReliableSettings(monotonicity_max_fraction=min(0.9, fraction - 0.05),
                                        use_curvature=False)
    _, report = reliable.reliable_candidates(s, guarded)
    assert report.skipped.get("monotonicity") == [0]
    assert report.removed["monotonicity"] == 0


def test_guard_is_per_region(scene):
    truth, scan = scene
    tables = [database.make_table(_spec("heldout_random_fabric")),
              database.make_table(_spec("heldout_gold_medium"))]
    region = np.zeros(scan.mask.shape, dtype=int)
    region[:, 48:] = 1
    parts = []
    for i in (0, 1, 2):
        light = synthetic.LIGHTS[i]
        photo = np.where((region == 0)[..., None], synthetic.photo(tables[0], truth, light),
                         synthetic.photo(tables[1], truth, light))
        parts.append(observations.observe(photo, scan.normal, scan.position,
                                          np.ones(scan.mask.shape), region,
                                          scan.camera_center, light, view_index=i))
    s = observations.concatenate(parts)
    strict = reliable.ReliableSettings(monotonicity_max_fraction=1.0, use_curvature=False)
    fraction = []
    for r in (0, 1):
        _, rep = reliable.reliable_candidates(s.subset(np.flatnonzero(s.region == r)), strict)
        fraction.append(rep.removed["monotonicity"] / rep.input)
    assert fraction[0] > fraction[1]  # the sheen breaks Eq. 1 more than the gold
    between = reliable.ReliableSettings(monotonicity_max_fraction=sum(fraction) / 2,
                                        use_curvature=False)
    _, report = reliable.reliable_candidates(s, between)
    assert report.skipped["monotonicity"] == [0]
    assert report.removed["monotonicity"] > 0  # still applied in the gold region
