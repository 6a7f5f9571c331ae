"""Refinements of the chosen trial (core.method.refine), on the numpy test scene (no
bpy): refitted to every observed pixel (``photo_consistent``) or to each photo's
radiance sum under bounds at the peak (``energy_consistent``, the default)."""

import dataclasses

import numpy as np
import pytest

from brdf_reconstruct.core.brdf import energy, merl, metrics
from brdf_reconstruct.core.method import pipeline, refine, reliable
from brdf_reconstruct.core.method.reconstruct import reconstruct
from testkit import synthetic

RES = 96
SETTINGS = pipeline.PipelineSettings(n_samples=12, n_trials=2, seed=3)


def _inputs(table, exact=True, lights=(0, 1, 2), irradiance=1.0):
    """Photos of ``table`` on the true height field with the truth's own G-buffers
    (exact normals) or the blunted scan's."""
    z = synthetic.height_field(RES)
    truth = synthetic.gbuffer_from_heights(z)
    g = truth if exact else synthetic.gbuffer_from_heights(synthetic.blunted(z, rng=1))
    return [pipeline.PhotoInput(
        photo=synthetic.photo(table, truth, synthetic.LIGHTS[i], irradiance=irradiance),
        normal=g.normal, position=g.position, visibility=np.ones(z.shape),
        region=np.zeros(z.shape, dtype=np.int64), camera_center=g.camera_center,
        light=synthetic.LIGHTS[i], irradiance=irradiance, name=f"photo{i}")
        for i in lights]


def _samples(inputs):
    samples, _ = pipeline.observe_photos(inputs, SETTINGS)
    trusted, _ = reliable.reliable_candidates(samples, SETTINGS.reliable)
    return samples, trusted


def _basis_table(basis, rng):
    """A table the basis spans exactly: the reconstruction of random coefficients
    drawn from the basis' own prior (unit-norm training columns)."""
    start = reconstruct(basis, np.array([[0, 0, 0]]), np.full((1, 3), 0.1))
    coefs = rng.normal(0.0, 0.5 / np.sqrt(basis.info["n_columns"]),
                       (basis.n_components, 3))
    return dataclasses.replace(start, coefficients=coefs).expand(), coefs


def test_a_table_in_the_basis_span_is_recovered_from_its_photos(default_basis):
    """Round trip: photos of a table the basis spans, exact normals, started from the
    basis mean (all coefficients 0): the refit reproduces the photos, and the table
    where they see it; elsewhere (directions no photo holds) the prior decides, so
    the whole table is only asked to come 10x closer than the start."""
    table, coefs = _basis_table(default_basis, np.random.default_rng(0))
    samples, trusted = _samples(_inputs(table))
    start = reconstruct(default_basis, trusted.cells[:1], trusted.rho[:1])
    start = dataclasses.replace(start, coefficients=np.zeros_like(coefs))
    refined = refine.photo_consistent(default_basis, start, samples, trusted)
    assert refine.relative_rmse(start, samples) > 0.05
    assert refine.relative_rmse(refined, samples) < 1e-3
    seen = merl.linear_index(samples.cells)
    true_rho = table.reshape(3, -1)[:, seen].T
    assert np.max(np.abs(refined.rho_at(seen) / true_rho - 1.0)) < 0.01
    assert (metrics.sphere_error(refined.table, table)
            < metrics.sphere_error(start.table, table) / 10)


def test_the_mirror_peak_is_kept_with_exact_normals(default_basis, heldout_tables):
    """The trials' log-space fit loses a mirror's highlight (most of its energy); the
    refit to the photos keeps it: the sphere error falls at least 3x, and the photos
    are reproduced within 2 % (no noise, exact normals)."""
    truth = heldout_tables["heldout_silver_mirror"]
    inputs = _inputs(truth)
    plain = pipeline.run(default_basis, inputs,
                         dataclasses.replace(SETTINGS, refine="none")).regions[0]
    refined = pipeline.run(default_basis, inputs,
                           dataclasses.replace(SETTINGS, refine="photo")).regions[0]
    assert refined.refinement["trial"] == plain.winner
    assert refined.refinement["after"] < 0.02 < refined.refinement["before"]
    before = metrics.sphere_error(plain.table, truth)
    after = metrics.sphere_error(refined.table, truth)
    assert after < before / 3
    assert np.all(np.isfinite(refined.table)) and np.all(refined.table >= 0)


@pytest.mark.parametrize("name", ["heldout_near_black", "heldout_silver_mirror"])
def test_refined_tables_stay_finite_at_the_extremes(default_basis, heldout_tables, name):
    """A near-black material (photos near 0) and a mirror (peaks 10^4 above its
    diffuse level), on the blunted scan with float32 photos: finite, >= 0."""
    inputs = [dataclasses.replace(p, photo=p.photo.astype(np.float32))
              for p in _inputs(heldout_tables[name], exact=False)]
    samples, trusted = _samples(inputs)
    start = reconstruct(default_basis, trusted.cells, trusted.rho)
    refined = refine.photo_consistent(default_basis, start, samples, trusted)
    assert np.all(np.isfinite(refined.coefficients))
    table = refined.table
    assert np.all(np.isfinite(table)) and np.all(table >= 0)
    assert np.isfinite(refine.relative_rmse(refined, samples))


def test_same_input_same_refined_table(default_basis, heldout_tables):
    inputs = _inputs(heldout_tables["heldout_rough_plastic"], exact=False)
    settings = dataclasses.replace(SETTINGS, refine="photo")
    a = pipeline.run(default_basis, inputs, settings).regions[0].table
    b = pipeline.run(default_basis, inputs, settings).regions[0].table
    assert np.array_equal(a, b)


def test_the_energy_refit_is_the_default_and_bad_settings_refused(default_basis,
                                                                   heldout_tables):
    assert pipeline.PipelineSettings().refine == "energy"
    with pytest.raises(ValueError, match="refine must be one of none, energy, photo"):
        pipeline.PipelineSettings(refine="yes")
    samples, trusted = _samples(_inputs(heldout_tables["heldout_rough_plastic"]))
    start = reconstruct(default_basis, trusted.cells, trusted.rho)
    for fit in (refine.photo_consistent, refine.energy_consistent):
        with pytest.raises(ValueError, match="iterations must be at least 1"):
            fit(default_basis, start, samples, trusted, iterations=0)
        with pytest.raises(ValueError, match="no observed samples"):
            fit(default_basis, start, samples.subset(np.array([], int)), trusted)
    for name, value in (("energy_sigma", 0.0), ("energy_sigma", np.nan), ("peak_sigma", -1.0)):
        with pytest.raises(ValueError, match=f"{name} must be a finite number > 0"):
            refine.energy_consistent(default_basis, start, samples, trusted, **{name: value})
    off = dataclasses.replace(SETTINGS, refine="none")
    result = pipeline.run(default_basis, _inputs(heldout_tables["heldout_rough_plastic"]),
                          off).regions[0]
    assert result.refinement == {} and result.refine_inputs is None
    assert "refinement" not in result.timings


def _true_energy(table, lights=(0, 1, 2)):
    """Radiance of ``table`` summed over the photos of the true height field."""
    truth = synthetic.gbuffer_from_heights(synthetic.height_field(RES))
    return sum(float(np.sum(synthetic.photo(table, truth, synthetic.LIGHTS[i])))
               for i in lights)


@pytest.mark.parametrize("name", ["heldout_silver_mirror", "heldout_aluminium_polished"])
def test_a_mirror_on_a_blunted_scan_keeps_half_its_energy(default_basis, heldout_tables, name):
    """Issue 15: on the blunted scan the chosen trial of a mirror-like material keeps
    less than half the light its photos hold (its highlight lost); the energy refit
    gives back at least half (measured on the true geometry, against the true
    table), comes closer to the true table, and its radiance on the scan rises
    towards the photos' (``refinement["energy_after"]``)."""
    truth = heldout_tables[name]
    inputs = _inputs(truth, exact=False)
    plain = pipeline.run(default_basis, inputs, dataclasses.replace(SETTINGS, refine="none"))
    kept = pipeline.run(default_basis, inputs, SETTINGS).regions[0]
    plain = plain.regions[0]
    assert kept.refinement["method"] == "energy" and kept.refinement["trial"] == plain.winner
    true = _true_energy(truth)
    assert _true_energy(plain.table) / true < 0.5
    assert _true_energy(kept.table) / true >= 0.5
    assert kept.refinement["energy_after"] > kept.refinement["energy_before"] + 0.2
    assert metrics.sphere_error(kept.table, truth) < metrics.sphere_error(plain.table, truth)
    assert np.all(np.isfinite(kept.table)) and np.all(kept.table >= 0)


def test_the_peak_stays_within_its_bounds(default_basis, heldout_tables):
    """Eq. (2) as a bound: the refitted table at theta_h = 0 and each photo's
    brightest pixel's theta_d, shaded as a pixel on the half vector, is within the
    bounds' softness of the larger of that pixel's value and the trial's; at every
    other theta_d it is at most the trial's peak lifted by the same gain. And with
    the bounds off the same sums take the mirror's peak higher than with them."""
    truth = heldout_tables["heldout_silver_mirror"]
    samples, trusted = _samples(_inputs(truth, exact=False))
    start = reconstruct(default_basis, trusted.cells[::4], trusted.rho[::4])
    bounded = refine.energy_consistent(default_basis, start, samples, trusted)
    free = refine.energy_consistent(default_basis, start, samples, trusted, peak_bound=False)
    views = np.asarray(samples.view)
    for v in np.unique(views):
        i = np.flatnonzero(views == v)[np.argmax(samples.radiance[views == v].sum(axis=1))]
        cell = samples.cells[i]
        row = np.column_stack([np.zeros(90, int), np.arange(90), np.full(90, cell[2])])
        rho_trial = start.rho_at(merl.linear_index(row))
        rho_new = bounded.rho_at(merl.linear_index(row))
        b = int(cell[1])
        pixel_rho = samples.radiance[i] / (samples.irradiance[i] * np.cos(np.radians(b + 0.5)))
        gain = np.maximum(1.0, pixel_rho / rho_trial[b])
        slack = 1.0 + 3 * refine.PEAK_SIGMA
        assert np.all(rho_new[b] <= np.maximum(pixel_rho, rho_trial[b]) * slack)
        assert np.all(rho_new <= rho_trial * gain * slack)
    top = (0, slice(None), slice(0, 60))
    assert (free.table[:, 0, :60].max() > bounded.table[:, 0, :60].max())
    assert np.all(np.isfinite(bounded.table[(slice(None),) + top]))


def test_pixel_noise_in_the_normals_is_measured_and_keeps_the_trial(default_basis,
                                                                     heldout_tables):
    """``normal_noise``: 0 on a plane and on a surface whose normal turns evenly, the
    jitter's size on jittered normals; the pipeline keeps the chosen trial, and says
    why in one sentence, where it is above ``MAX_NORMAL_NOISE_DEG``."""
    h, w = 40, 50
    plane = np.zeros((h, w, 3))
    plane[..., 2] = 1.0
    mask = np.ones((h, w), bool)
    assert refine.normal_noise([plane], [mask]) < 1e-6
    angle = np.radians(np.linspace(-40.0, 40.0, w))[None, :].repeat(h, axis=0)
    cylinder = np.stack([np.sin(angle), np.zeros_like(angle), np.cos(angle)], axis=-1)
    assert refine.normal_noise([cylinder], [mask]) < 1e-3
    noisy = _turned(plane, 3.0, np.random.default_rng(0))
    assert 3.0 < refine.normal_noise([noisy], [mask]) < 6.0  # about 1.2 x 3 degrees
    assert refine.normal_noise([plane], [np.zeros((h, w), bool)]) == 0.0

    truth = heldout_tables["heldout_silver_mirror"]
    smooth = pipeline.run(default_basis, _inputs(truth, exact=False), SETTINGS).regions[0]
    assert smooth.refinement["normal_noise_deg"] < refine.MAX_NORMAL_NOISE_DEG
    assert "skipped" not in smooth.refinement and "energy_after" in smooth.refinement
    jittered = pipeline.run(default_basis, _jittered(_inputs(truth), 3.0), SETTINGS).regions[0]
    assert jittered.refinement["normal_noise_deg"] > refine.MAX_NORMAL_NOISE_DEG
    assert "normals change from pixel to pixel" in jittered.refinement["skipped"]
    assert jittered.refine_inputs is None
    np.testing.assert_array_equal(jittered.table, jittered.candidates[jittered.winner])


def test_a_trial_that_keeps_the_photos_energy_is_refitted_unless_textured(default_basis,
                                                                        heldout_tables):
    """A Lambert on exact normals: the chosen trial's radiance on the scan is already
    within ENERGY_TOLERANCE of the photos'. The energy refit still runs on untextured
    photos (a skip there measured worse on the blunted bunny: two-layer gold 0.27
    against 0.19 refitted, docs/results.md); with the every-pixel judge off it meets
    the photos' sums at least as well as the trial and takes the table no further from
    the truth on the sphere. Where the photos were divided by a texture whose albedo
    was fitted to the trial (``normalised``), the trial is kept and the report says
    why. (With the judge on, the every-pixel refit, which reproduces these photos, is
    the table and the energy refit is not tried.)"""
    truth = heldout_tables["heldout_lambert_grey"]
    inputs = _inputs(truth)
    region = pipeline.run(default_basis, inputs, SETTINGS).regions[0]
    before = region.refinement["energy_before"]
    assert abs(before - 1.0) <= refine.ENERGY_TOLERANCE
    assert region.refinement["table"] == "every_pixel" and "skipped" not in region.refinement
    pipeline.refine_chosen(region, photo_consistent=0.0)
    assert region.refinement["table"] == "energy" and "skipped" not in region.refinement
    assert abs(region.refinement["energy_after"] - 1.0) <= abs(before - 1.0) + 1e-3
    trial = metrics.sphere_error(region.candidates[region.winner], truth)
    assert metrics.sphere_error(region.table, truth) <= trial  # measured 0.024 against 0.080

    # the same chosen trial, its photos marked as divided by a texture
    region.refine_inputs = dataclasses.replace(region.refine_inputs, normalised=True)
    pipeline.refine_chosen(region, photo_consistent=0.0)
    assert "divided by an albedo fitted to the chosen trial" in region.refinement["skipped"]
    assert "already within 5 % of theirs" in region.refinement["skipped"]
    assert region.refinement["table"] == "trial"
    np.testing.assert_array_equal(region.table, region.candidates[region.winner])


@pytest.mark.parametrize("name", ["heldout_gold_medium", "heldout_silver_mirror"])
def test_the_photos_are_read_pixel_by_pixel_where_the_scan_allows(default_basis,
                                                                  heldout_tables, name):
    """Photo consistency as the judge (pipeline.refine_chosen). On exact normals the
    chosen trial refitted to every pixel reproduces each photo (relative RMSE at the
    photos' own level here: no noise) and predicts each from the other two, so it
    is the table, and it is nearer the true table than the energy refit alone
    (measured: gold 0.008 against 0.058, silver 0.029 against 0.184; asked: 2x).
    On the blunted scan the same refit misses the photos (0.7 to 1.0), so the
    table is the energy refinement's, bit for bit."""
    truth = heldout_tables[name]
    exact = pipeline.run(default_basis, _inputs(truth), SETTINGS).regions[0]
    judged = exact.refinement["every_pixel"]
    assert exact.refinement["table"] == "every_pixel" and judged["kept"]
    assert max(judged["per_photo"]) <= SETTINGS.photo_consistent
    assert max(judged["held_out"]) <= SETTINGS.photo_consistent
    every = metrics.sphere_error(exact.table, truth)
    pipeline.refine_chosen(exact, photo_consistent=0.0)
    assert every < metrics.sphere_error(exact.table, truth) / 2

    blunted = pipeline.run(default_basis, _inputs(truth, exact=False), SETTINGS).regions[0]
    judged = blunted.refinement["every_pixel"]
    assert not judged["kept"] and blunted.refinement["table"] != "every_pixel"
    assert min(judged["per_photo"]) > SETTINGS.photo_consistent
    assert judged["held_out"] is None  # not asked for: the refit already missed
    table = blunted.table.copy()
    pipeline.refine_chosen(blunted, photo_consistent=0.0)
    np.testing.assert_array_equal(table, blunted.table)


def test_the_every_pixel_refit_bounded_in_albedo_reflects_no_more_than_it_receives(
        default_basis, heldout_tables):
    """Exact photos of the silver under three lights: the every-pixel refit
    reproduces them (relative RMSE 1e-4) but fills directions no photo sees with
    twice the light the surface receives (largest directional albedo 2.0; the
    truth's 0.975). With ``max_albedo=1`` it reproduces the photos as well, its
    albedo comes within the bound's softness of 1 (measured 1.04), and the table
    comes nearer the truth (measured sphere error 0.008 against 0.029)."""
    truth = heldout_tables["heldout_silver_mirror"]
    region = pipeline.run(default_basis, _inputs(truth), SETTINGS).regions[0]
    inp = region.refine_inputs
    start = region.candidates.reconstructions[region.winner]
    free = refine.photo_consistent(inp.basis, start, inp.observed, inp.trusted)
    bounded = refine.photo_consistent(inp.basis, start, inp.observed, inp.trusted,
                                      max_albedo=1.0)
    assert energy.largest_albedo(free.table) > 1.5
    assert energy.largest_albedo(bounded.table) < 1.0 + 25 * refine.ALBEDO_SIGMA
    assert refine.relative_rmse(bounded, inp.observed) < 0.002
    assert (metrics.sphere_error(bounded.table, truth)
            < metrics.sphere_error(free.table, truth))
    assert np.all(np.isfinite(bounded.table)) and np.all(bounded.table >= 0)
    for bad in (0.0, -1.0, np.nan, np.inf):
        with pytest.raises(ValueError, match="max_albedo must be a finite number > 0"):
            refine.photo_consistent(inp.basis, start, inp.observed, inp.trusted,
                                    max_albedo=bad)


def test_an_energy_refit_that_reads_the_photos_worse_than_the_trial_is_not_kept(
        default_basis, heldout_tables):
    """Exact normals let the photos be read pixel by pixel: the silver's one photo
    (light 2) is reproduced by the every-pixel refit to 1e-4, but one photo cannot
    be held out, so that refit is not kept and the energy refit is tried. It
    reproduces the photo worse than the chosen trial (measured: relative RMSE 0.115
    against 0.103), so the trial is the table and the report says why. (Here the
    sphere prefers the refit a little, 0.203 against 0.226; on the textured numpy
    scene's exact scan the same rule took the silver from 1.07 to 0.16 and the
    polished aluminium from 1.08 to 0.33: docs/results.md.) On the blunted scan no
    refit reads the photo, and the energy refit is kept as before."""
    truth = heldout_tables["heldout_silver_mirror"]
    region = pipeline.run(default_basis, _inputs(truth, lights=(2,)), SETTINGS).regions[0]
    judged = region.refinement["every_pixel"]
    assert max(judged["per_photo"]) <= SETTINGS.photo_consistent and not judged["kept"]
    inp = region.refine_inputs
    start = region.candidates.reconstructions[region.winner]
    energy_refit = refine.energy_consistent(inp.basis, start, inp.observed, inp.trusted,
                                            **inp.options)
    trial_rmse = refine.relative_rmse(start, inp.observed)
    assert refine.relative_rmse(energy_refit, inp.observed) > trial_rmse
    assert region.refinement["table"] == "trial"
    assert "read pixel by pixel" in region.refinement["skipped"]
    assert f"{trial_rmse:.3f} ->" in region.refinement["skipped"]
    np.testing.assert_array_equal(region.table, region.candidates[region.winner])

    blunted = pipeline.run(default_basis, _inputs(truth, exact=False, lights=(2,)),
                           SETTINGS).regions[0]
    assert blunted.refinement["every_pixel"]["held_out"] is None  # not read
    assert blunted.refinement["table"] == "energy"


def test_a_refit_that_hangs_on_each_photo_but_halves_the_trials_error_is_kept(
        default_basis, heldout_tables, monkeypatch):
    """The polished aluminium under two lights, exact normals: refitted from one
    photo alone, the every-pixel refit moves on the sphere by more than a judge of
    0.15 allows (measured 0.16 to 0.21: each photo alone sees part of the lobe),
    but predicts the photo left out far better than the chosen trial fits it
    (0.02 to 0.025 against 0.17 to 0.19). The photos say it is the better table,
    so it is kept ("against the trial"), and it is nearer the truth than the
    energy refit (measured 0.042 against 0.190; asked: 2x). The user's own photos
    are not asked how much light the refit reflects; photos divided by a texture
    an earlier table made are (``normalised``): the refit reflects 0.91 of the
    light at normal view, as the truth does, but 1.29 at 80 degrees, where no
    photo looks, above refine.MAX_ALBEDO, so there the judge turns it down and
    the energy refit is the table; allowed that much light, it is kept. The refits
    here are free (no ``refine.ALBEDO_BOUND``, as on photos divided by a texture):
    bounded, this refit hangs on each photo less and is kept by its own errors
    (the next test)."""
    monkeypatch.setattr(refine, "ALBEDO_BOUND", None)
    truth = heldout_tables["heldout_aluminium_polished"]
    region = pipeline.run(default_basis, _inputs(truth, lights=(0, 2)), SETTINGS).regions[0]
    judge = 0.15  # below the dependence on each photo, above the refit's own misses
    pipeline.refine_chosen(region, photo_consistent=judge)
    judged = region.refinement["every_pixel"]
    assert judged["kept"] and judged["by"] == "against the trial"
    assert region.refinement["table"] == "every_pixel"
    assert np.median(judged["dependence"]) > judge
    assert (np.median(judged["held_out"])
            <= refine.TRIAL_SHARE * np.median(judged["trial_per_photo"]))
    assert judged["trial_share"] == refine.TRIAL_SHARE
    assert judged["largest_albedo"] is None  # not asked of the user's own photos
    kept = metrics.sphere_error(region.table, truth)
    region.refine_inputs = dataclasses.replace(region.refine_inputs, normalised=True)
    pipeline.refine_chosen(region, photo_consistent=judge)
    judged = region.refinement["every_pixel"]
    assert not judged["kept"] and judged["by"] is None
    assert judged["largest_albedo"] > refine.MAX_ALBEDO
    assert region.refinement["table"] != "every_pixel"
    assert kept < metrics.sphere_error(region.table, truth) / 2
    largest = judged["largest_albedo"]
    monkeypatch.setattr(refine, "MAX_ALBEDO", 2.0 * largest)
    pipeline.refine_chosen(region, photo_consistent=judge)
    judged = region.refinement["every_pixel"]
    assert judged["kept"] and judged["by"] == "against the trial"
    assert judged["largest_albedo"] == pytest.approx(largest, rel=1e-9)
    assert judged["largest_albedo"] == pytest.approx(
        energy.largest_albedo(region.table), rel=1e-9)
    assert metrics.sphere_error(region.table, truth) == pytest.approx(kept, rel=1e-6)


def test_the_judges_refit_reflects_no_more_than_it_receives_textured_or_not(
        default_basis, heldout_tables, monkeypatch):
    """The previous test's capture (polished aluminium, two lights, exact normals,
    judge 0.15). The photos see part of the lobe; refitted to every pixel without a
    bound, the table fills the rest with light: it reflects 1.77 of what it receives
    (measured) and hangs on each photo by 0.18 to 0.20 on the sphere. Bounded at
    ``refine.ALBEDO_BOUND`` (1.0), as the pipeline refits the user's own photos, it
    reflects no more than 1.05, hangs on each photo by 0.07, is kept by its own
    errors and is nearer the truth (measured 0.018 against the free refit's 0.031;
    asked: better by 20 %). Photos divided by a texture (``normalised``) are
    bounded the same way: their table is at the region's mean colour, no brighter
    than its brightest texel, a surface (before 2026-12-07 their refits were free)."""
    truth = heldout_tables["heldout_aluminium_polished"]
    judge = 0.15
    inputs = _inputs(truth, lights=(0, 2))
    assert refine.ALBEDO_BOUND == 1.0
    region = pipeline.run(default_basis, inputs, SETTINGS).regions[0]
    pipeline.refine_chosen(region, photo_consistent=judge)
    judged = region.refinement["every_pixel"]
    assert judged["albedo_bound"] == refine.ALBEDO_BOUND and "bound_refused" not in judged
    assert judged["kept"] and judged["by"] == "its own errors"
    assert region.refinement["table"] == "every_pixel"
    assert energy.largest_albedo(region.table) <= 1.05
    bounded = metrics.sphere_error(region.table, truth)
    table = region.table
    region.refine_inputs = dataclasses.replace(region.refine_inputs, normalised=True)
    pipeline.refine_chosen(region, photo_consistent=judge)
    judged = region.refinement["every_pixel"]
    assert judged["albedo_bound"] == refine.ALBEDO_BOUND and judged["kept"]
    np.testing.assert_array_equal(region.table, table)
    monkeypatch.setattr(refine, "ALBEDO_BOUND", None)
    free = pipeline.run(default_basis, inputs, SETTINGS).regions[0]
    pipeline.refine_chosen(free, photo_consistent=judge)
    assert free.refinement["every_pixel"]["albedo_bound"] is None
    assert free.refinement["table"] == "every_pixel"
    assert energy.largest_albedo(free.table) > 1.5
    assert np.median(free.refinement["every_pixel"]["dependence"]) > judge
    assert bounded < 0.8 * metrics.sphere_error(free.table, truth)


def test_a_reconstructions_albedo_read_from_its_coefficients_is_its_tables(default_basis,
                                                                          heldout_tables):
    """refine.reconstruction_albedo reads a reconstruction's largest directional
    albedo at the quadrature's cells only; it is energy.directional_albedo of the
    expanded table on the same nodes (reference value), and those nodes are
    energy.largest_albedo's: the bound and the judge read the same cells (60 nodes
    until 2026-12-07, 0.01 from it)."""
    region = pipeline.run(default_basis, _inputs(heldout_tables["heldout_gold_medium"]),
                          SETTINGS).regions[0]
    rec = region.candidates.reconstructions[region.winner]
    got = refine.reconstruction_albedo(rec)
    want = float(np.max(energy.directional_albedo(rec.table, energy.CHECK_ANGLES_DEG,
                                                  refine.ALBEDO_NODES, refine.ALBEDO_NODES)))
    assert got == pytest.approx(want, rel=1e-10)
    assert got == pytest.approx(energy.largest_albedo(rec.table), rel=1e-10)
    assert 0.5 < got < 1.5  # the gold's trial: near the truth's 0.92


def test_a_bounded_refit_keeps_its_bound_where_the_table_is_read(default_basis,
                                                                 heldout_tables):
    """The polished aluminium on the blunted scan under two lights, refitted to
    every pixel with ``max_albedo=1``: the bound holds the table only at the cells
    its quadrature reads (``refine.ALBEDO_NODES`` per axis). Read there and by
    ``energy.largest_albedo`` (the judge's and the texture bench's measure) the
    refit stays within the bound's softness (measured 1.0000 both). Held at 60
    nodes, as until 2026-12-07, it read 1.0000 there and 1.029 at 120: the light
    went between the nodes."""
    assert refine.ALBEDO_NODES == 120
    truth = heldout_tables["heldout_aluminium_polished"]
    region = pipeline.run(default_basis, _inputs(truth, exact=False, lights=(0, 2)),
                          SETTINGS).regions[0]
    inp = region.refine_inputs
    start = region.candidates.reconstructions[region.winner]
    bounded = refine.photo_consistent(inp.basis, start, inp.observed, inp.trusted,
                                      max_albedo=1.0)
    limit = 1.0 + 5 * refine.ALBEDO_SIGMA
    assert refine.reconstruction_albedo(bounded) <= limit
    assert energy.largest_albedo(bounded.table) <= limit
    assert np.all(np.isfinite(bounded.table)) and np.all(bounded.table >= 0)


def test_photos_brighter_than_their_irradiance_allows_refuse_the_albedo_bound(
        default_basis, heldout_tables, monkeypatch):
    """Exact photos of the gold whose given irradiance is 4 times too low (a
    default of 1 with a camera's own units): the table they imply is 4 x the truth,
    whose albedo reaches 3.7. Bounded at ALBEDO_BOUND, the every-pixel refit misses
    each photo (measured 0.55 to 0.63 against the judge's 0.2) and the energy refit
    is the table (sphere 0.140 against 4 x the truth); the free refit meets them
    (0.00), so the photos refuse the bound: the refit is free, kept (measured
    0.056), and the report says the irradiance is likely too low (the sentence the
    panel and the batch run show, pipeline.refinement_notes). The 'photo'
    refinement (Refine to Photos) does the same."""
    truth = 4.0 * heldout_tables["heldout_gold_medium"]
    inputs = [dataclasses.replace(p, irradiance=0.25)
              for p in _inputs(heldout_tables["heldout_gold_medium"])]
    region = pipeline.run(default_basis, inputs, SETTINGS).regions[0]
    judged = region.refinement["every_pixel"]
    assert "irradiance is likely too low" in judged["bound_refused"]
    assert pipeline.refinement_notes(region.refinement) == [judged["bound_refused"]]
    assert judged["albedo_bound"] is None and judged["kept"]
    assert region.refinement["table"] == "every_pixel"
    assert energy.largest_albedo(region.table) > 3.0
    refused = metrics.sphere_error(region.table, truth)
    assert refused < 0.1
    monkeypatch.setattr(refine, "BOUND_PRESSED", np.inf)  # the bound always holds
    held = pipeline.run(default_basis, inputs, SETTINGS).regions[0]
    assert "bound_refused" not in held.refinement["every_pixel"]
    assert pipeline.refinement_notes(held.refinement) == []
    assert held.refinement["table"] == "energy"
    assert refused < 0.6 * metrics.sphere_error(held.table, truth)
    monkeypatch.undo()
    photo = pipeline.run(default_basis, inputs,
                         dataclasses.replace(SETTINGS, refine="photo")).regions[0]
    assert photo.refinement["albedo_bound"] is None
    assert "irradiance is likely too low" in photo.refinement["bound_refused"]
    assert pipeline.refinement_notes(photo.refinement) == [photo.refinement["bound_refused"]]
    assert metrics.sphere_error(photo.table, truth) < 0.1


def test_how_far_the_table_hangs_on_each_photo_is_its_sphere_error(default_basis,
                                                                     heldout_tables):
    """refine.photo_dependence reads the refits' radiance on the rendered sphere from
    their coefficients; it is metrics.sphere_error of the expanded tables (the
    reference value), 0 for the refit itself, NaN where a photo has no refit. On
    exact normals the gold's refit hardly hangs on any photo (measured 0.02 to
    0.03), so the judge keeps it."""
    region = pipeline.run(default_basis, _inputs(heldout_tables["heldout_gold_medium"]),
                          SETTINGS).regions[0]
    inp = region.refine_inputs
    start = region.candidates.reconstructions[region.winner]
    every = refine.photo_consistent(inp.basis, start, inp.observed, inp.trusted)
    got = refine.photo_dependence(every, [every, start, None])
    assert got[0] == pytest.approx(0.0, abs=1e-12) and np.isnan(got[2])
    assert got[1] == pytest.approx(metrics.sphere_error(start.table, every.table), rel=1e-9)
    judged = region.refinement["every_pixel"]
    assert judged["kept"] and max(judged["dependence"]) <= 0.1


def test_esc_during_the_judge_stops_between_refits_and_changes_nothing(default_basis,
                                                                       heldout_tables):
    """The judge's held-out refits (one per photo, about 0.3 to 0.8 s each) poll Esc:
    cancelled after the first, refine_chosen raises Cancelled and leaves the
    region's table and record as they were; not cancelled, it refits as before."""
    region = pipeline.run(default_basis, _inputs(heldout_tables["heldout_gold_medium"]),
                          SETTINGS).regions[0]
    assert region.refinement["every_pixel"]["held_out"] is not None  # the refits ran
    table, record = region.table.copy(), dict(region.refinement)
    polls = []

    def cancelled():
        polls.append(1)
        return len(polls) >= 2  # Esc pressed during the first held-out refit

    with pytest.raises(pipeline.Cancelled):
        pipeline.refine_chosen(region, cancelled=cancelled)
    assert len(polls) == 2
    np.testing.assert_array_equal(region.table, table)
    assert region.refinement == record
    pipeline.refine_chosen(region, cancelled=lambda: False)
    np.testing.assert_array_equal(region.table, table)


def test_the_energy_per_photo_follows_each_photo(default_basis, heldout_tables):
    """energy_ratios: one ratio per photo, and a photo twice as bright halves its own
    ratio and no other; energy_agreement: the mean and spread of their logarithms,
    finite for a trial that predicts nothing and for a single photo."""
    region = pipeline.run(default_basis, _inputs(heldout_tables["heldout_gold_medium"]),
                          SETTINGS).regions[0]
    observed = region.refine_inputs.observed
    trial = region.candidates.reconstructions[region.winner]
    before = refine.energy_ratios(trial, observed)
    assert before.shape == (3,) and np.all(np.isfinite(before)) and np.all(before > 0)
    brighter = np.asarray(observed.radiance, dtype=np.float64).copy()
    brighter[np.asarray(observed.view) == np.unique(observed.view)[1]] *= 2.0
    after = refine.energy_ratios(trial, dataclasses.replace(observed, radiance=brighter))
    np.testing.assert_allclose(after, before * [1.0, 0.5, 1.0], rtol=1e-12)
    shortfall, spread = refine.energy_agreement([0.5, 0.5, 0.5])
    assert shortfall == pytest.approx(np.log(0.5)) and spread == pytest.approx(0.0, abs=1e-12)
    shortfall, spread = refine.energy_agreement([0.5, 2.0])
    assert shortfall == pytest.approx(0.0, abs=1e-12)
    assert spread == pytest.approx(np.log(4.0) / np.sqrt(2.0))
    assert all(np.isfinite(refine.energy_agreement([0.0, 1.0])))
    assert refine.energy_agreement([0.3]) == (pytest.approx(np.log(0.3)), 0.0)
    assert refine.energy_misfit([1.0, 1.0, 1.0]) == 0.0 and refine.energy_misfit([]) == 0.0
    assert refine.energy_misfit(np.exp([0.1, -0.1])) == pytest.approx(0.1)
    assert np.isfinite(refine.energy_misfit([0.0, 1.0]))


def test_photos_that_disagree_on_the_energy_keep_the_trial(default_basis, heldout_tables):
    """No table meets every photo's sum when the photos disagree on it (a scan whose
    shape or shadows give each photo a different share of its light: Suzanne's
    capture measured 0.71, 0.99, 1.28 and 1.71 for one trial, and the refit turned
    its gold to copper). Here the gold's photos are 0.5x, 1x and 2x as bright as the
    table says on exact normals: the trial scatters about the photos' energy by more
    than it misses it, and the refit cannot meet the three sums, so the trial is
    kept as it is, and the report says why."""
    inputs = _inputs(heldout_tables["heldout_gold_medium"])
    inputs = [dataclasses.replace(p, photo=p.photo * s)
              for p, s in zip(inputs, (0.5, 1.0, 2.0), strict=True)]
    region = pipeline.run(default_basis, inputs, SETTINGS).regions[0]
    ratios = region.refinement["energy_per_photo"]
    shortfall, spread = refine.energy_agreement(ratios)
    assert abs(region.refinement["energy_before"] - 1.0) > refine.ENERGY_TOLERANCE
    assert abs(shortfall) <= spread
    after = region.refinement["energy_per_photo_after"]
    assert refine.energy_misfit(after) > refine.ENERGY_RECONCILED
    assert "the refit does not reconcile them" in region.refinement["skipped"]
    np.testing.assert_array_equal(region.table, region.candidates[region.winner])


def test_a_refit_that_meets_each_photo_only_where_it_alone_looks_is_not_kept(
        default_basis, heldout_tables, monkeypatch):
    """The gold's photos made 0.5x, 1x and 2x as bright. Free (no
    ``refine.ALBEDO_BOUND``, as on photos divided by a texture), the every-pixel
    refit meets each one on its own cells to a relative RMSE under the judge's
    threshold (measured 0.17, 0.08, 0.02), by bending the table where no photo
    looks (a peak of 10^9 at grazing theta_d, sphere error 5 x 10^4). Refitted to
    two photos it does not predict the third, so it is not kept, and the table
    stays finite and no worse than the trial. Bounded, it cannot bend the table that
    far and misses the photos (measured 1.05 on the darkest): not kept either, and
    the same holds of the table. As the pipeline refits the user's photos, the
    free refit meeting each photo where the bounded one cannot refuses the bound
    (the photos say more light than the irradiance given), and is then judged,
    and not kept, as above."""
    truth = heldout_tables["heldout_gold_medium"]
    inputs = _inputs(truth)
    inputs = [dataclasses.replace(p, photo=p.photo * s)
              for p, s in zip(inputs, (0.5, 1.0, 2.0), strict=True)]

    def table_is_no_worse(region):
        assert region.refinement["table"] != "every_pixel"
        assert np.all(np.isfinite(region.table))
        assert (metrics.sphere_error(region.table, truth)
                <= metrics.sphere_error(region.candidates[region.winner], truth) + 1e-12)

    refused = pipeline.run(default_basis, inputs, SETTINGS).regions[0]
    judged = refused.refinement["every_pixel"]
    assert "bound_refused" in judged and judged["albedo_bound"] is None
    assert not judged["kept"]
    table_is_no_worse(refused)
    monkeypatch.setattr(refine, "BOUND_PRESSED", np.inf)  # the bound always holds
    bounded = pipeline.run(default_basis, inputs, SETTINGS).regions[0]
    judged = bounded.refinement["every_pixel"]
    assert judged["albedo_bound"] == refine.ALBEDO_BOUND and "bound_refused" not in judged
    assert max(judged["per_photo"]) > SETTINGS.photo_consistent and not judged["kept"]
    table_is_no_worse(bounded)
    monkeypatch.setattr(refine, "ALBEDO_BOUND", None)
    region = pipeline.run(default_basis, inputs, SETTINGS).regions[0]
    judged = region.refinement["every_pixel"]
    assert max(judged["per_photo"]) <= SETTINGS.photo_consistent
    assert np.median(judged["held_out"]) > SETTINGS.photo_consistent and not judged["kept"]
    # nor against the trial: the held-out photos are missed by more than half the
    # trial's own error (measured 0.36 against 0.48)
    assert (np.median(judged["held_out"])
            > refine.TRIAL_SHARE * np.median(judged["trial_per_photo"]))
    assert len(judged["dependence"]) == 3  # recorded beside it
    table_is_no_worse(region)


def test_photos_that_disagree_but_are_reconciled_keep_the_refit():
    """The rule of refine_chosen (refine.photos_disagree_unreconciled), case by case:
    photos that agree on the trial's shortfall keep the refit whatever it reaches;
    photos that disagree keep it only when it meets every photo's sum (a sheen the
    trial misses differently in each view: photo_bench's random fabric on exact Spot
    went 0.14 -> 0.43 without this half of the rule); otherwise the trial stays."""
    agree = np.exp([-0.5, -0.45, -0.55])  # all short by e^-0.5: agreed
    disagree = np.exp([-0.3, 0.0, 0.3])  # mean 0, spread 0.3
    reconciled = np.exp([0.05, -0.05, 0.0])  # RMS log 0.041 <= ENERGY_RECONCILED
    split = np.exp([-0.2, 0.0, 0.2])  # RMS log 0.163: no table met all three
    assert refine.energy_misfit(reconciled) <= refine.ENERGY_RECONCILED
    assert refine.energy_misfit(split) > refine.ENERGY_RECONCILED
    assert not refine.photos_disagree_unreconciled(agree, split)
    assert not refine.photos_disagree_unreconciled(agree, reconciled)
    assert not refine.photos_disagree_unreconciled(disagree, reconciled)
    assert refine.photos_disagree_unreconciled(disagree, split)
    assert not refine.photos_disagree_unreconciled([0.5], [0.6])  # one photo agrees with itself
    assert not refine.photos_disagree_unreconciled([], [])


@pytest.mark.filterwarnings("error::RuntimeWarning")
def test_a_trial_far_off_the_photos_refits_without_overflow(default_basis, heldout_tables):
    """A chosen trial far off the photos (its coefficients times -5: its peak cells
    underflow to nothing beneath the photos' brightest pixels, 0.64 of their energy):
    the peak bounds are formed in logarithms, so nothing overflows (every
    RuntimeWarning is an error here; before, the gain's division overflowed), and the
    refit is finite and nearer the photos' energy than the trial."""
    region = pipeline.run(default_basis, _inputs(heldout_tables["heldout_gold_medium"]),
                          SETTINGS).regions[0]
    start = region.candidates.reconstructions[region.winner]
    wild = dataclasses.replace(start, coefficients=-5.0 * start.coefficients)
    observed = region.refine_inputs.observed
    before = refine.energy_ratio(wild, observed)
    refined = refine.energy_consistent(default_basis, wild, observed, region.refine_inputs.trusted)
    after = refine.energy_ratio(refined, observed)
    assert np.all(np.isfinite(refined.table))
    assert abs(np.log(after)) < abs(np.log(before))


@pytest.mark.filterwarnings("error::RuntimeWarning")
def test_a_channel_without_light_refits_without_warnings(default_basis, heldout_tables):
    """Photos holding no light in one channel (the blue of a pure red object; a black
    channel): that channel's sums and peak bounds are 0, and the refit's
    uncertainties, relative to them, are floored above float64's underflow (they were
    0: a division by zero, then NaN in the objective). The refit stays finite and
    predicts nothing in blue."""
    inputs = _inputs(heldout_tables["heldout_gold_medium"], exact=False)
    for p in inputs:
        p.photo[..., 2] = 0.0
    region = pipeline.run(default_basis, inputs, SETTINGS).regions[0]
    start = region.candidates.reconstructions[region.winner]
    observed, trusted = region.refine_inputs.observed, region.refine_inputs.trusted
    refined = refine.energy_consistent(default_basis, start, observed, trusted)
    assert np.all(np.isfinite(refined.table))
    assert np.all(np.isfinite(refined.coefficients))


def _rise(table):
    """How far a table climbs with theta_h near its peak: the summed positive steps of
    log rho from one theta_h bin to the next, theta_h bins 0-30, every 3rd theta_d,
    phi_d 0/45/90/135 degrees (refine's ladder), over pairs of measured (finite,
    positive) cells; 0 for a table falling with theta_h."""
    with np.errstate(divide="ignore", invalid="ignore"):
        x = np.log(table[:, :31, ::3, [0, 45, 90, 135]])
    step = np.diff(x, axis=1)
    return float(np.sum(np.maximum(step[np.isfinite(step)], 0.0)))


@pytest.mark.parametrize("name", ["heldout_silver_mirror", "heldout_glossy_plastic",
                                  "heldout_gold_medium"])
def test_the_refit_keeps_the_peak_falling_with_theta_h(default_basis, heldout_tables, name):
    """On the blunted scan the energy sums alone are met by a ring where the scan's
    normals put the highlight (the table climbs with theta_h: measured 0.3 -> 353 for
    the glossy plastic); the monotone term (the paper's own assumption, intensity
    falling with n.h) keeps the refitted table at most half as climbing, while the
    photos' energy is met as well as without it (within 3 %). The true tables hardly
    climb (silver 3.1, at theta_d >= 60 degrees, where the shadowing ends its lobe)."""
    assert _rise(heldout_tables[name]) < 5.0
    region = pipeline.run(default_basis, _inputs(heldout_tables[name], exact=False),
                          SETTINGS).regions[0]
    start = region.candidates.reconstructions[region.winner]
    observed, trusted = region.refine_inputs.observed, region.refine_inputs.trusted
    free = refine.energy_consistent(default_basis, start, observed, trusted, monotone=False)
    held = refine.energy_consistent(default_basis, start, observed, trusted)
    assert _rise(held.table) < 0.5 * _rise(free.table)
    assert abs(refine.energy_ratio(held, observed) - refine.energy_ratio(free, observed)) < 0.03
    assert np.all(np.isfinite(held.table))


def test_same_input_same_energy_refit(default_basis, heldout_tables):
    inputs = _inputs(heldout_tables["heldout_glossy_plastic"], exact=False)
    a = pipeline.run(default_basis, inputs, SETTINGS).regions[0].table
    b = pipeline.run(default_basis, inputs, SETTINGS).regions[0].table
    assert np.array_equal(a, b)


def test_a_new_winner_is_refitted(default_basis, heldout_tables):
    """The Cycles path may choose another trial: refine_chosen refits that one."""
    inputs = _inputs(heldout_tables["heldout_rough_plastic"])
    r = pipeline.run(default_basis, inputs, dataclasses.replace(SETTINGS, refine="photo"))
    region = r.regions[0]
    other = 1 - region.winner
    region.winner = other
    pipeline.refine_chosen(region)
    assert region.refinement["trial"] == other
    samples, trusted = region.refine_inputs.observed, region.refine_inputs.trusted
    again = refine.photo_consistent(default_basis, region.candidates.reconstructions[other],
                                    samples, trusted)
    assert np.array_equal(region.table, again.table)


def _turned(normal, degrees, rng):
    """Unit normals (..., 3), each turned by an independent Gaussian tangent offset
    of ``degrees`` standard deviation per axis."""
    d = rng.normal(0.0, np.radians(degrees), normal.shape)
    d -= np.sum(d * normal, axis=-1, keepdims=True) * normal
    m = normal + d
    return m / np.linalg.norm(m, axis=-1, keepdims=True)


def _jittered(inputs, degrees, seed=0):
    """The photos' G-buffer normals turned as :func:`_turned` does (scan noise)."""
    rng = np.random.default_rng(seed)
    return [dataclasses.replace(p, normal=_turned(p.normal, degrees, rng)) for p in inputs]


@pytest.mark.parametrize("degrees", [1.0, 2.0])
@pytest.mark.parametrize("name", ["heldout_gold_medium", "heldout_glossy_plastic",
                                  "heldout_silver_mirror"])
def test_a_highlight_seen_with_jittered_normals_keeps_its_peak(default_basis, heldout_tables,
                                                               name, degrees):
    """Photos on the true surface, normals jittered by 1 or 2 degrees: the default
    pipeline (the trials and the energy refit, not the refit to every pixel) keeps
    the specular peak (theta_h bin 0, theta_d below 60
    degrees, the largest value per channel) within a factor 2 of the true one, for
    a GGX gold (alpha 0.12), a glossy plastic and a mirror 10^4 above its diffuse
    level. (The refit does not: with 1 degree its mirror peak is 10^3 too high;
    module docstring.)"""
    truth = heldout_tables[name]
    inputs = _jittered(_inputs(truth), degrees)
    table = pipeline.run(default_basis, inputs, SETTINGS).regions[0].table
    ratio = table[:, 0, :60].max(axis=(1, 2)) / truth[:, 0, :60].max(axis=(1, 2))
    assert np.all((ratio > 0.5) & (ratio < 2.0)), ratio


def _blurred_inputs(table, degrees, draws=16, seed=7):
    """Photos whose every pixel is the mean over ``draws`` true normals turned
    (:func:`_turned`; a lobe blurred by normal error), with the exact normals as the
    scan's."""
    z = synthetic.height_field(RES)
    g = synthetic.gbuffer_from_heights(z)
    rng = np.random.default_rng(seed)
    out = []
    for i in (0, 1, 2):
        total = 0.0
        for _ in range(draws):
            turned = dataclasses.replace(g, normal=_turned(g.normal, degrees, rng))
            total = total + synthetic.photo(table, turned, synthetic.LIGHTS[i])
        out.append(pipeline.PhotoInput(
            photo=total / draws, normal=g.normal, position=g.position,
            visibility=np.ones(z.shape), region=np.zeros(z.shape, dtype=np.int64),
            camera_center=g.camera_center, light=synthetic.LIGHTS[i], irradiance=1.0,
            name=f"photo{i}"))
    return out


@pytest.mark.parametrize("name", ["heldout_gold_medium", "heldout_glossy_plastic"])
def test_the_normal_error_model_undoes_a_known_blur(default_basis, heldout_tables, name):
    """Photos blurred by a known 2-degree normal error (independent draws): the refit
    told that error (``normal_sigma``) comes at least 1.4x closer to the true table
    than the refit that takes the scan's normals as exact, which fits the blurred
    lobe (measured 0.245 / 0.140 for the gold, 0.578 / 0.250 for the plastic)."""
    truth = heldout_tables[name]
    samples, trusted = _samples(_blurred_inputs(truth, 2.0))
    start = reconstruct(default_basis, trusted.cells[:1], trusted.rho[:1])
    start = dataclasses.replace(start, coefficients=np.zeros((default_basis.n_components, 3)))
    plain = refine.photo_consistent(default_basis, start, samples, trusted)
    told = refine.photo_consistent(default_basis, start, samples, trusted,
                                   normal_sigma=np.radians(2.0))
    assert np.all(np.isfinite(told.table))
    e_plain = metrics.sphere_error(plain.table, truth)
    e_told = metrics.sphere_error(told.table, truth)
    assert e_told * 1.4 < e_plain, (e_told, e_plain)


def test_the_normal_error_model_is_validated_and_deterministic(default_basis, heldout_tables):
    """A negative or NaN normal_sigma and fewer than one draw are refused in one
    sentence; zero is the plain refit to the bit; the draws are seeded."""
    inputs = _inputs(heldout_tables["heldout_gold_medium"])
    samples, trusted = _samples(inputs)
    start = reconstruct(default_basis, trusted.cells[:20], trusted.rho[:20])
    for bad in (-0.01, float("nan"), float("inf")):
        with pytest.raises(ValueError, match="normal_sigma"):
            refine.photo_consistent(default_basis, start, samples, trusted, normal_sigma=bad)
    with pytest.raises(ValueError, match="normal_draws"):
        refine.photo_consistent(default_basis, start, samples, trusted, normal_sigma=0.01,
                                normal_draws=0)
    plain = refine.photo_consistent(default_basis, start, samples, trusted, iterations=3)
    zero = refine.photo_consistent(default_basis, start, samples, trusted, iterations=3,
                                   normal_sigma=0.0)
    assert np.array_equal(plain.coefficients, zero.coefficients)
    a, b = (refine.photo_consistent(default_basis, start, samples, trusted, iterations=3,
                                    normal_sigma=0.02).coefficients for _ in range(2))
    assert np.array_equal(a, b)


def _footprint_scene(table, lights=(0, 1, 2)):
    """The numpy scene shaded 2 x 2 finer than its G-buffers: per light the photo a
    camera's pixel records (the mean radiance over its area: the finer photo
    averaged 2 x 2), the point-sampled photo (shaded at the pixel's own normal) and
    the G-buffers (each pixel's normal the normalised mean of its four finer ones,
    its position their mean; ``footprint_normal`` the four, (H, W, 4, 3))."""
    fine = synthetic.gbuffer_from_heights(synthetic.height_field(2 * RES))

    def blocks(a):  # (2H, 2W, ...) -> (H, W, 4, ...)
        a = a.reshape(RES, 2, RES, 2, *a.shape[2:]).swapaxes(1, 2)
        return a.reshape(RES, RES, 4, *a.shape[4:])

    footprint = blocks(fine.normal)
    normal = footprint.mean(axis=2)
    normal /= np.linalg.norm(normal, axis=-1, keepdims=True)
    coarse = synthetic.GBuffer(normal, blocks(fine.position).mean(axis=2),
                               np.ones((RES, RES), dtype=bool), fine.camera_center)
    out = []
    for i in lights:
        light = synthetic.LIGHTS[i]
        area = blocks(synthetic.photo(table, fine, light)).mean(axis=2)
        base = dict(normal=coarse.normal, position=coarse.position,
                    visibility=np.ones((RES, RES)), region=np.zeros((RES, RES), dtype=np.int64),
                    camera_center=coarse.camera_center, light=light, name=f"photo{i}")
        out.append((pipeline.PhotoInput(photo=synthetic.photo(table, coarse, light), **base),
                    pipeline.PhotoInput(photo=area, **base),
                    pipeline.PhotoInput(photo=area, footprint_normal=footprint, **base)))
    return [list(x) for x in zip(*out, strict=True)]


def test_photos_averaged_over_each_pixel_are_read_with_the_pixels_footprint(
        default_basis, heldout_tables):
    """A camera's pixel records the mean radiance over its area; the scan's
    G-buffers give one normal per pixel. Where a highlight is narrower than a pixel
    that mean is not the radiance at the pixel's normal, and a refit reading the
    pixel at its centre misses the table (gold, exact normals: 5.2x the
    point-sampled photos' error when written). Given the normals at four points of
    each pixel (``PhotoInput.footprint_normal``), the refits predict each pixel as
    their mean: then 1.6x (the trials, the KL and the mapped term still read the
    pixel at its centre)."""
    truth = heldout_tables["heldout_gold_medium"]
    point, area, footprint = _footprint_scene(truth)
    error = {name: metrics.sphere_error(pipeline.run(default_basis, inputs,
                                                     SETTINGS).regions[0].table, truth)
             for name, inputs in (("point", point), ("area", area),
                                  ("footprint", footprint))}
    assert error["area"] > 3.0 * error["point"], error
    assert error["footprint"] < 0.5 * error["area"], error
    assert error["footprint"] < 2.0 * error["point"], error


def test_a_region_over_the_refits_sample_cap_is_read_through_a_uniform_draw(
        default_basis, heldout_tables, monkeypatch):
    """refine.refit_samples: at most the cap of the observed samples and the same share
    of the trusted ones, each photo's brightest sample per channel kept, the rest a
    fixed uniform draw (the same for every call), and a region under the cap read
    whole (the same objects: every number measured so far is unchanged). A draw of a
    sixth of the samples refits a table the basis spans as well as all of them: it
    reproduces every pixel, the five sixths it never read included."""
    table, coefs = _basis_table(default_basis, np.random.default_rng(0))
    samples, trusted = _samples(_inputs(table))
    whole = refine.refit_samples(samples, trusted)
    assert whole[0] is samples and whole[1] is trusted  # under the cap
    cap = len(samples) // 6
    drawn, drawn_trusted = refine.refit_samples(samples, trusted, cap)
    assert len(drawn) == cap
    assert len(drawn_trusted) == round(len(trusted) * cap / len(samples))
    again, _ = refine.refit_samples(samples, trusted, cap)
    np.testing.assert_array_equal(drawn.pixel, again.pixel)
    np.testing.assert_array_equal(drawn.view, again.view)
    for v in np.unique(samples.view):
        np.testing.assert_array_equal(drawn.radiance[drawn.view == v].max(axis=0),
                                      samples.radiance[samples.view == v].max(axis=0))
    # each photo's share of the draw is its share of the samples, to sampling noise
    share = np.bincount(drawn.view) / cap
    assert np.allclose(share, np.bincount(samples.view) / len(samples), atol=0.02)
    start = reconstruct(default_basis, trusted.cells[:1], trusted.rho[:1])
    start = dataclasses.replace(start, coefficients=np.zeros_like(coefs))
    refined = refine.photo_consistent(default_basis, start, drawn, drawn_trusted)
    assert refine.relative_rmse(refined, samples) < 1e-3
    # the energy each photo holds, read from the draw, is read from all to 3 %
    np.testing.assert_allclose(refine.energy_ratios(start, drawn),
                               refine.energy_ratios(start, samples), rtol=0.03)
    with pytest.raises(ValueError, match="at_most must be at least 1"):
        refine.refit_samples(samples, trusted, 0)
    # the pipeline reads the draw and says so
    monkeypatch.setattr(refine, "MAX_REFIT_SAMPLES", cap)
    region = pipeline.run(default_basis, _inputs(table), SETTINGS).regions[0]
    assert region.counts["refit"] == cap and len(region.refine_inputs.observed) == cap
    assert region.counts["observed"] == len(samples)
    assert region.counts["refit_trusted"] == len(region.refine_inputs.trusted) < len(trusted)
