"""Textured regions on the numpy scene (core.method.textured, issue 16): one shared
BRDF shape and an albedo per texel, against the truth the photos were made from
(a texture of 17:1 scaling the analytic material's diffuse lobe, exact normals)."""

from __future__ import annotations

import dataclasses
import hashlib

import numpy as np
import pytest

from brdf_reconstruct.core.brdf import database, metrics
from brdf_reconstruct.core.method import albedo, pipeline, refine, textured
from testkit import synthetic

RES = 96
SHAPE = (24, 24)
SETTINGS = pipeline.PipelineSettings(n_samples=20, n_trials=8, seed=0)
TEXTURE = textured.TextureSettings(shape=SHAPE)
# the variants that test the refits, not the alternation: 3 rounds, as they were
# measured (the defaults' 8 rounds cost the suite minutes)
SHORT = textured.TextureSettings(shape=SHAPE, rounds=3, tolerance=0.005)
SPECS = {s["name"]: s for s in database.heldout_specs()}


def scene_inputs(spec, texture, *, with_uv=True):
    """Three photos of the true height field (1 % noise), its own G-buffers as the scan."""
    truth = synthetic.gbuffer_from_heights(synthetic.height_field(RES))
    colour, rest = synthetic.colour_tables(spec)
    return synthetic.textured_inputs(colour, rest, texture, SHAPE, truth, truth,
                                     with_uv=with_uv)


@pytest.fixture(scope="module", params=["heldout_lambert_grey", "heldout_glossy_plastic"])
def runs(request, default_basis):
    """Per material: the truth, the untextured capture's table, the method on the
    textured photos as they are, and the textured reconstruction, with the default
    settings (the energy refit, judged against the every-pixel refit), under
    ``"energy"`` the same three with the energy refit alone (``photo_consistent=0``)
    and, under ``"trials"``, without a refit (the chosen trial as it is), these two
    with the alternation's earlier 3 rounds (``SHORT``)."""
    spec = SPECS[request.param]
    tex = synthetic.patch_texture(SHAPE)
    inputs = scene_inputs(spec, tex)
    digests = [hashlib.sha256(p.photo.tobytes()).hexdigest() for p in inputs]

    def three(settings, texture=TEXTURE):
        untextured = pipeline.run(default_basis, scene_inputs(spec, np.ones_like(tex)),
                                  settings)
        naive = pipeline.run(default_basis, inputs, settings)
        result = textured.run(default_basis, inputs, settings, texture)
        return dict(untextured=untextured.regions[0].table, naive=naive.regions[0].table,
                    result=result)

    return dict(name=request.param, truth=database.make_table(spec), texture=tex, inputs=inputs,
                digests=digests, **three(SETTINGS),
                energy=three(dataclasses.replace(SETTINGS, photo_consistent=0.0), SHORT),
                trials=three(dataclasses.replace(SETTINGS, refine="none"), SHORT))


def test_the_albedo_map_of_a_textured_scene_is_recovered(runs):
    assert runs["texture"].max() / runs["texture"].min() >= 10.0
    texture = runs["result"].textures[0]
    measured = texture.map.coverage == albedo.MEASURED
    assert measured.mean() > 0.95
    truth = runs["texture"] / runs["texture"][measured].mean(axis=0)
    error = np.abs(texture.relative() - truth) / truth
    # measured (2026-12-03): median 0.5 % (Lambert), 0.5-1.1 % per channel (glossy plastic)
    assert np.median(error[measured]) <= 0.02
    assert not texture.map.constant and texture.model == "diffuse"


def test_the_shared_shape_is_near_the_untextured_capture(runs):
    """The textured photos as they are mix the texture into the shape; the shared
    shape comes back near the untextured capture's (the chosen trials, no refit;
    measured: Lambert 0.25 naive, 0.03 untextured, 0.07 textured; glossy plastic
    0.32, 0.09, 0.12)."""
    trials = runs["trials"]
    err = {k: metrics.sphere_error(trials[k], runs["truth"])
           for k in ("untextured", "naive")}
    shared = metrics.sphere_error(trials["result"].result.regions[0].table, runs["truth"])
    assert shared < 0.5 * err["naive"]
    assert shared <= err["untextured"] + 0.05
    assert np.isfinite(trials["result"].result.regions[0].table).all()


def test_keeping_the_energy_does_not_spoil_the_shared_shape(runs):
    """With the energy refit alone none of the three comes out worse than the
    chosen trial, and the shared shape stays better than the naive one. The
    untextured and naive photos are always refitted; the shared shape, whose photos
    were divided by an albedo fitted to its trial, is refitted only where the trial
    misses their energy by more than 5 % (refine.ENERGY_TOLERANCE; without that skip
    the glossy plastic's shared shape went 0.096 to 0.125 and the Lambert's 0.052
    to 0.021, 2026-12-05)."""
    truth, energy = runs["truth"], runs["energy"]
    for key in ("untextured", "naive"):
        assert (metrics.sphere_error(energy[key], truth)
                <= metrics.sphere_error(runs["trials"][key], truth) + 1e-12)
    shared = metrics.sphere_error(energy["result"].result.regions[0].table, truth)
    assert shared <= metrics.sphere_error(
        runs["trials"]["result"].result.regions[0].table, truth) + 1e-12
    assert shared < metrics.sphere_error(energy["naive"], truth)
    assert np.isfinite(energy["result"].result.regions[0].table).all()


def test_the_judged_refit_keeps_the_shared_shape_near_the_truth(runs):
    """With the defaults (the every-pixel refit kept where it reproduces the
    albedo-divided photos: here it does, to 1.4 %) the shared shape stays far better
    than the naive one and within 0.05 of the untextured capture's trial. Measured
    (2026-12-04): Lambert 0.032 (trial 0.039, untextured 0.015), glossy plastic
    0.097 (trial 0.091: 7 % worse, untextured 0.066)."""
    truth = runs["truth"]
    region = runs["result"].result.regions[0]
    shared = metrics.sphere_error(region.table, truth)
    assert region.refinement["table"] == "every_pixel"
    assert shared < 0.5 * metrics.sphere_error(runs["naive"], truth)
    assert shared <= metrics.sphere_error(runs["trials"]["untextured"], truth) + 0.05
    assert np.isfinite(region.table).all()
    # the photos were divided by a texture the previous table made; the judge weighs
    # the refit against the trial as on untextured photos, and would ask it to
    # conserve energy too
    assert region.refine_inputs.normalised
    assert region.refinement["every_pixel"]["trial_share"] == refine.TRIAL_SHARE


def test_the_alternation_goes_on_until_the_texture_settles(runs):
    """Texture and shape trade slowly from round to round (each round's change of the
    texture small, but in the same direction), so the alternation runs until the
    texture moves by less than 0.1 % (``TextureSettings``: up to 8 rounds). Measured
    (2026-12-07, the defaults' judged refit): the Lambert's shared shape 0.019 against
    the untextured capture's 0.015 in 3 rounds (1.29x), 0.030 (2.07x) when it stopped
    at a 0.5 % change after 2; the glossy plastic 0.077 against 0.066 (1.17x; 1.27x).
    Asked: within 1.5x, and more than 2 rounds for the Lambert."""
    assert TEXTURE.tolerance <= 0.001 and TEXTURE.rounds >= 8
    result = runs["result"]
    shared = metrics.sphere_error(result.result.regions[0].table, runs["truth"])
    assert shared <= 1.5 * metrics.sphere_error(runs["untextured"], runs["truth"])
    changes = [r["0"]["change"] for r in result.rounds[1:]]
    assert len(result.rounds) == TEXTURE.rounds or changes[-1] < TEXTURE.tolerance
    assert all(c >= TEXTURE.tolerance for c in changes[:-1])
    if runs["name"] == "heldout_lambert_grey":
        assert len(result.rounds) > 2


def _texture(tex, model, table):
    """A measured RegionTexture of relative albedo ``tex`` ((texels, 3), mean 1)."""
    n = len(tex)
    m = albedo.AlbedoMap(shape=SHAPE, albedo=0.4 * tex, coverage=np.full(n, albedo.MEASURED,
                         np.uint8), observations=np.ones(n, np.int64),
                         reference=np.full(3, 0.4), constant=False, reason="", stats={})
    return textured.RegionTexture(map=m, model=model, delta=textured.diffuse_level(table),
                                  noise={}, misfit={})


@pytest.mark.parametrize(("name", "model"), [("heldout_gold_medium", "whole"),
                                           ("heldout_lambert_grey", "diffuse")])
def test_the_photos_are_brought_to_the_reference_exactly(name, model):
    """normalised_inputs: photos of a texture (17:1, no noise) over the true table
    (a tinted metal, whose whole value scales; a Lambert, whose whole value is its
    diffuse part) become the untextured photos given the true texture. Where the
    whole value scales they are divided by the colour, so whatever table estimated
    the texture (3x the truth, or black) leaks nothing into the next fit (the
    additive form did: the numpy scene's gold 0.328 against 0.117 untextured);
    the diffuse model's additive form is exact under the true table and off by
    a share ``1 - a_t / reference`` of a wrong one."""
    truth_table = database.make_table(SPECS[name])
    tex = synthetic.patch_texture(SHAPE)
    assert tex.min() >= textured.RATIO_FLOOR
    scan = synthetic.gbuffer_from_heights(synthetic.height_field(RES))
    zero = np.zeros_like(truth_table)
    textured_photos = synthetic.textured_inputs(truth_table, zero, tex, SHAPE, scan, scan,
                                                noise=0.0)
    plain = synthetic.textured_inputs(truth_table, zero, np.ones_like(tex), SHAPE, scan, scan,
                                      noise=0.0)
    uvs = textured.check_uvs(textured_photos)
    texture = {0: _texture(tex, model, truth_table)}

    def brought(table):
        return textured.normalised_inputs(textured_photos, uvs, texture, {0: table}, SHAPE)

    for o, w, b, q, t in zip(brought(truth_table), brought(3.0 * truth_table), brought(zero),
                             plain, textured_photos, strict=True):
        if model == "whole":
            for out in (o, w, b):
                np.testing.assert_allclose(out.photo, q.photo, rtol=1e-9, atol=1e-12)
            continue
        # the table holds no value at the most grazing pixels (n.l below 0.011
        # here, a handful): the additive form leaves them as they are
        has = (textured.table_at_pixels(truth_table, t) > 0).all(axis=2)
        lit = (t.photo > 0).any(axis=2)
        assert (~has & lit).sum() <= 0.005 * lit.sum()
        np.testing.assert_allclose(o.photo[has], q.photo[has], rtol=1e-6, atol=1e-9)
        assert not np.allclose(w.photo[has], q.photo[has], rtol=1e-3)


def test_the_users_photos_are_not_changed(runs):
    assert [hashlib.sha256(p.photo.tobytes()).hexdigest() for p in runs["inputs"]] == \
        runs["digests"]


def test_the_rounds_are_reported(runs):
    rounds = runs["result"].rounds
    assert 1 <= len(rounds) <= TEXTURE.rounds
    assert rounds[0]["0"]["change"] is None
    assert all(r["0"]["change"] >= 0.0 for r in rounds[1:])
    summary = runs["result"].summary()
    assert summary["texture"]["0"]["model"] in textured.MODELS
    assert "initial_albedo" in summary["timings_s"]


def test_a_homogeneous_region_gets_a_constant_and_the_methods_own_table(default_basis):
    """Without a texture the region gets one colour, and the table is the method's
    on the same photos, to the bit (nothing was normalised)."""
    spec = SPECS["heldout_rough_plastic"]
    inputs = scene_inputs(spec, np.ones((SHAPE[0] * SHAPE[1], 3)))
    plain = pipeline.run(default_basis, inputs, SETTINGS)
    result = textured.run(default_basis, inputs, SETTINGS, TEXTURE)
    texture = result.textures[0]
    assert texture.map.constant, texture.map.reason
    assert len(result.rounds) == 1
    np.testing.assert_array_equal(result.result.regions[0].table, plain.regions[0].table)


def test_same_seed_same_texture(default_basis):
    spec = SPECS["heldout_lambert_grey"]
    inputs = scene_inputs(spec, synthetic.patch_texture(SHAPE, seed=3))
    settings = pipeline.PipelineSettings(n_samples=12, n_trials=2, seed=5)
    quick = textured.TextureSettings(shape=SHAPE, rounds=1, initial_iterations=1)
    a = textured.run(default_basis, inputs, settings, quick)
    b = textured.run(default_basis, inputs, settings, quick)
    np.testing.assert_array_equal(a.textures[0].map.albedo, b.textures[0].map.albedo)
    np.testing.assert_array_equal(a.result.regions[0].table, b.result.regions[0].table)


def test_a_scan_without_uvs_gets_one_sentence(default_basis):
    inputs = scene_inputs(SPECS["heldout_lambert_grey"], np.ones((SHAPE[0] * SHAPE[1], 3)),
                          with_uv=False)
    with pytest.raises(ValueError, match="photo0: the scan has no UV map"):
        textured.run(default_basis, inputs, SETTINGS, TEXTURE)


@pytest.mark.parametrize("name, value", [("rounds", 0), ("initial_iterations", -1),
                                         ("tolerance", 0.0), ("shape", (0, 8))])
def test_out_of_range_texture_settings_are_refused(name, value):
    with pytest.raises(ValueError, match="texture setting|texture shape"):
        textured.TextureSettings(**{name: value})


def test_colour_part_caps_the_scaling_at_twice_the_diffuse_level():
    values = np.array([[0.1, 0.2, 0.3], [1.0, 1.0, 1.0]])
    d, s = textured.colour_part(values, np.array([0.1, 0.1, 0.1]))
    np.testing.assert_allclose(d, [[0.1, 0.2, 0.2], [0.2, 0.2, 0.2]])
    np.testing.assert_allclose(d + s, values)
    whole, rest = textured.colour_part(values, np.array([0.1, 0.1, 0.1]), np.inf)
    np.testing.assert_array_equal(whole, values)
    assert not rest.any()


def test_the_diffuse_level_of_a_lambert_table_is_its_albedo_over_pi(heldout_tables):
    level = textured.diffuse_level(heldout_tables["heldout_lambert_grey"])
    np.testing.assert_allclose(level, 0.18 / np.pi, rtol=1e-6)


def test_the_whole_model_of_a_table_without_diffuse_has_no_nan():
    values = np.array([[0.0, 0.5, 3.0]])
    d, s = textured.colour_part(values, np.zeros(3), np.inf)  # a mirror: delta 0
    np.testing.assert_array_equal(d, values)
    assert np.isfinite(s).all()


def test_a_region_whose_observations_constrain_no_color_keeps_the_tables(heldout_tables):
    """A black table (nothing scales) under black photos: one constant color of 1 and a
    reason, not an error that would end the run."""
    from brdf_reconstruct.core.method import observations

    n = 50
    cells = np.tile([[10, 20, 30]], (n, 1))
    samples = observations.Samples(
        n=np.tile([0.0, 0.0, 1.0], (n, 1)), l=np.tile([0.0, 0.0, 1.0], (n, 1)),
        v=np.tile([0.0, 0.0, 1.0], (n, 1)), rho=np.zeros((n, 3)), radiance=np.zeros((n, 3)),
        irradiance=np.ones((n, 3)), cells=cells, view=np.zeros(n, dtype=np.int64),
        pixel=np.zeros((n, 2), dtype=np.int64), region=np.zeros(n, dtype=np.int64),
        curvature=np.zeros(n))
    black = np.zeros_like(heldout_tables["heldout_lambert_grey"])
    t = textured.estimate_texture(black, samples, np.arange(n) % 16, (4, 4),
                                  albedo.AlbedoSettings())
    assert t.map.constant and t.map.reason.startswith("One constant color: no observation")
    assert (t.relative() == 1.0).all() and (t.map.coverage == albedo.FILLED).all()



def test_a_region_the_first_albedo_cannot_fit_starts_from_its_photos(default_basis,
                                                                     monkeypatch):
    """When nothing constrains a first albedo (``initial_albedo`` refuses), the first
    fit sees the photos as they are: the run goes on, as with no first albedo."""
    inputs = scene_inputs(SPECS["heldout_lambert_grey"], synthetic.patch_texture(SHAPE))

    def refuse(*args, **kwargs):
        raise ValueError("no observation constrains this region's albedo")

    monkeypatch.setattr(textured, "initial_albedo", refuse)
    quick = textured.TextureSettings(shape=SHAPE, rounds=1)
    result = textured.run(default_basis, inputs, SETTINGS, quick)
    plain = textured.run(default_basis, inputs, SETTINGS, dataclasses.replace(
        quick, initial_iterations=0))
    np.testing.assert_array_equal(result.result.regions[0].table, plain.result.regions[0].table)


def _textured_samples(parts, tex, shape, n=40_000, seed=0):
    """Observations of a textured surface (normals within 40 degrees of +z; four
    photos, each its own light and view): Samples, each observation's texel. The
    texture scales ``parts[0]``; ``parts[1]`` does not (tables (3, 90, 90, 180))."""
    from brdf_reconstruct.core.brdf import merl
    from brdf_reconstruct.core.method import observations

    rng = np.random.default_rng(seed)
    view = rng.integers(0, 4, n)
    angle = np.radians([10.0, 35.0, 55.0, 25.0])[view]
    light = np.stack([np.sin(angle), np.zeros(n), np.cos(angle)], axis=1)
    camera = np.stack([-np.sin(angle / 2), 0.3 * np.ones(n), np.ones(n)], axis=1)
    camera /= np.linalg.norm(camera, axis=1, keepdims=True)
    tilt = np.radians(40.0) * np.sqrt(rng.random(n))
    phi = rng.uniform(0, 2 * np.pi, n)
    normal = np.stack([np.sin(tilt) * np.cos(phi), np.sin(tilt) * np.sin(phi), np.cos(tilt)], 1)
    ok = (np.sum(normal * light, 1) > 0.05) & (np.sum(normal * camera, 1) > 0.05)
    normal, light, camera, view = normal[ok], light[ok], camera[ok], view[ok]
    m = len(view)
    cells = merl.cells_about_normals(normal, light, camera)
    texel = rng.integers(0, shape[0] * shape[1], m)
    values = [np.nan_to_num(p[:, cells[:, 0], cells[:, 1], cells[:, 2]].T) for p in parts]
    rho = tex[texel] * values[0] + values[1]
    rho *= 1.0 + 0.01 * rng.standard_normal(rho.shape)
    samples = observations.Samples(
        n=normal, l=light, v=camera, rho=rho, radiance=rho, irradiance=np.ones((m, 3)),
        cells=cells, view=view, pixel=np.zeros((m, 2), dtype=np.int64),
        region=np.zeros(m, dtype=np.int64), curvature=np.zeros(m))
    return samples, texel


@pytest.mark.parametrize("name, model", [("heldout_gold_medium", "whole"),
                                         ("heldout_glossy_plastic", "diffuse")])
def test_the_model_is_the_one_that_misses_the_observations_less(heldout_tables, name, model):
    """A gold whose whole table scales with the texture, and a plastic whose Lambert
    lobe does under a coat that does not: each gets its model, chosen by the same
    misfit for both (each model's own noise estimate read the gold's diffuse model
    as the quieter), and its texture to 2 %."""
    table = heldout_tables[name]
    colour, rest = synthetic.colour_tables(SPECS[name])
    parts = (colour, rest) if model == "diffuse" else (table, np.zeros_like(table))
    shape = (16, 16)
    tex = synthetic.patch_texture(shape, patch=4, seed=3)
    samples, texel = _textured_samples(parts, tex, shape)
    reference = tex.mean(axis=0)  # the table the texture's mean makes
    at_reference = parts[1] + parts[0] * reference[:, None, None, None]
    t = textured.estimate_texture(at_reference, samples, texel, shape, albedo.AlbedoSettings())
    assert t.model == model, (t.misfit, t.noise)
    assert t.misfit[model] < t.misfit["diffuse" if model == "whole" else "whole"]
    measured = t.map.coverage == albedo.MEASURED
    truth = tex[measured] / tex[measured].mean(axis=0)
    assert np.median(np.abs(t.relative()[measured] - truth) / truth) <= 0.02



@pytest.mark.parametrize("name", ["alumina-oxide", "blue-rubber"])
def test_a_whole_scaled_material_with_few_highlights_gets_the_whole_model(name):
    """Measured materials whose whole table scales with a 17:1 texture but whose
    highlights (the observations above the diffuse model's cap, where the two
    models differ) are under 3 % of the observations: over all observations the two
    misfits are within 7 %, so that margin chose the diffuse model and the shape
    was fitted to highlights divided by the wrong colour (the texture bench's exact
    numpy scene: alumina-oxide 0.436 against 0.172 untextured). The choice reads
    the misfits where the models differ."""
    from brdf_reconstruct.core.brdf import nbrdf
    from testkit import measured

    pack = nbrdf.load(measured.PACK)
    table = nbrdf.tabulate(pack, pack.index(name))
    shape = (16, 16)
    tex = synthetic.patch_texture(shape, patch=4, seed=3)
    samples, texel = _textured_samples((table, np.zeros_like(table)), tex, shape)
    at_reference = table * tex.mean(axis=0)[:, None, None, None]
    t = textured.estimate_texture(at_reference, samples, texel, shape, albedo.AlbedoSettings())
    assert 0 < t.highlight_observations < 0.03 * len(texel)
    assert t.misfit["whole"] > 0.9 * t.misfit["diffuse"]  # the margin could not tell
    assert t.model == "whole", (t.misfit, t.highlight_misfit)
    assert t.highlight_misfit["whole"] < 0.5 * t.highlight_misfit["diffuse"]
    measured_texels = t.map.coverage == albedo.MEASURED
    truth = tex[measured_texels] / tex[measured_texels].mean(axis=0)
    assert np.median(np.abs(t.relative()[measured_texels] - truth) / truth) <= 0.02


def test_highlights_that_miss_under_either_model_do_not_choose_it():
    """A blunted scan misplaces the highlights: both models miss them by more than
    ``HIGHLIGHT_MISFIT_MAX`` and the choice falls back to the misfit over all
    observations (on degraded Spot the whole model, chosen on such highlights,
    divided them by an albedo map 50 % off: the gold's shape 0.67 -> 4.3). Here the
    observations above the cap of a plastic whose Lambert lobe carries the texture
    are each off by a random factor (log sigma 0.5) and scale with the texel's
    colour too, so on them the whole model misses less, yet by more
    than the bound: the diffuse model is kept, as the misfit over all says."""
    name = "heldout_glossy_plastic"
    colour, rest = synthetic.colour_tables(SPECS[name])
    shape = (16, 16)
    tex = synthetic.patch_texture(shape, patch=4, seed=3)
    samples, texel = _textured_samples((colour, rest), tex, shape)
    reference = tex.mean(axis=0)
    at_reference = rest + colour * reference[:, None, None, None]
    c = samples.cells
    values = at_reference[:, c[:, 0], c[:, 1], c[:, 2]].T
    above = np.any(values > textured.CAP * textured.diffuse_level(at_reference), axis=1)
    rng = np.random.default_rng(5)
    rho = samples.rho.copy()
    rho[above] *= (tex[texel[above]] / reference) * np.exp(
        0.5 * rng.standard_normal((above.sum(), 1)))
    t = textured.estimate_texture(at_reference, dataclasses.replace(samples, rho=rho), texel,
                                  shape, albedo.AlbedoSettings())
    assert t.highlight_observations >= textured.MIN_HIGHLIGHT
    assert min(t.highlight_misfit.values()) > textured.HIGHLIGHT_MISFIT_MAX
    assert t.highlight_misfit["whole"] < textured.WHOLE_MARGIN * t.highlight_misfit["diffuse"]
    assert t.misfit["whole"] >= textured.WHOLE_MARGIN * t.misfit["diffuse"]
    assert t.model == "diffuse", (t.misfit, t.highlight_misfit)

def test_the_normal_sensitivity_is_the_lights_slant_on_a_lambertian_and_grows_on_a_lobes_flank():
    """g = sqrt(tan^2 theta_i + (d log rho / d theta_h)^2): a constant table has no
    slope, so g is tan(theta_i) exactly; a narrow lobe adds its log-slope."""
    import types

    from brdf_reconstruct.core.brdf import merl

    rng = np.random.default_rng(2)
    n = np.tile([0.0, 0.0, 1.0], (200, 1))
    theta = rng.uniform(0.0, 1.2, 200)
    l = np.column_stack([np.sin(theta), np.zeros(200), np.cos(theta)])  # noqa: E741
    v = np.tile([0.0, 0.0, 1.0], (200, 1))
    samples = types.SimpleNamespace(n=n, l=l, cells=merl.cells_about_normals(n, l, v))
    flat = textured.normal_sensitivity(samples, lambda c: np.full((len(c), 3), 0.3))
    np.testing.assert_allclose(flat, np.tan(theta), rtol=1e-9)
    th = merl.angles_from_cells(samples.cells)[0]

    def lobe(c):  # exp(-theta_h^2 / (2 0.05^2)): d log rho / d theta_h = -theta_h / 0.05^2
        t = merl.angles_from_cells(c)[0]
        return np.repeat(np.exp(-t**2 / (2 * 0.05**2))[:, None], 3, axis=1)

    steep = textured.normal_sensitivity(samples, lobe)
    assert (steep >= flat - 1e-9).all()
    inner = (samples.cells[:, 0] > 0) & (samples.cells[:, 0] < 89) & (th > 0.05) & (th < 0.3)
    np.testing.assert_allclose(steep[inner], np.hypot(np.tan(theta[inner]), th[inner] / 0.05**2),
                               rtol=0.1)


def test_a_scan_texture_that_won_a_near_comparison_gives_way_to_the_photos_own(measured_basis):
    """The numpy scene, exact scan, polished aluminium (its whole table scaled by the
    17:1 texture), the scan's texture baked as photogrammetry bakes it (the ambient
    occlusion and the sky's reflection in it: 7 % off), Balanced's settings. Under the
    shape fitted to it the scan's texture predicts each photo from the others at
    least as well as the photos' own (0.188 against 0.208), so it replaced theirs and
    the next shape followed it: 0.326 on the sphere against 0.144 untextured. Settled
    again with the photos' own texture (weighed with the scan's), that predicts the
    held-out photos to 0.131 and is kept: albedo 0.033, sphere 0.112 (texture bench,
    2026-12-08)."""
    from testkit.scan_texture import numpy_arrays, scan_texture

    name = "heldout_aluminium_polished"
    table = database.make_table(SPECS[name])
    truth = synthetic.gbuffer_from_heights(synthetic.height_field(RES))
    tex = synthetic.patch_texture(SHAPE, patch=4, seed=0)
    settings = pipeline.PipelineSettings(n_samples=20, n_trials=16, seed=0)  # Balanced's
    zero = np.zeros_like(table)
    inputs = synthetic.textured_inputs(table, zero, tex, SHAPE, truth, truth, rng_base=0)
    arrays = numpy_arrays(truth, truth)
    prior = scan_texture(arrays, table, zero, tex, SHAPE, arrays["ambient"])
    result = textured.run(measured_basis, inputs, settings, TEXTURE, prior=prior)
    t = result.textures[0]
    choice = result.choices["0"]
    assert choice["kept"] == "photos' texture", choice
    assert choice["photos_texture_misfit"] < choice["scan_texture_misfit"], choice
    assert t.map.stats["pattern"] == "photos and scan texture", t.map.reason
    assert "Tried both ways" in t.map.reason, t.map.reason
    assert t.summary()["choice"] == choice  # in the extension's report
    measured = t.map.measured
    truth_rel = tex / tex[measured].mean(axis=0)
    prior_rel = prior.reshape(-1, 3) / prior.reshape(-1, 3)[measured].mean(axis=0)
    error = np.median(np.abs(t.relative()[measured] - truth_rel[measured]) / truth_rel[measured])
    prior_error = np.median(np.abs(prior_rel[measured] - truth_rel[measured])
                            / truth_rel[measured])
    assert error < 0.6 * prior_error, (error, prior_error)  # measured 0.033 against 0.072
    untextured = pipeline.run(measured_basis, synthetic.textured_inputs(
        table, zero, np.ones_like(tex), SHAPE, truth, truth, rng_base=0), settings)
    at_reference = table * tex[measured].mean(axis=0)[:, None, None, None]
    shared = metrics.sphere_error(result.result.regions[0].table, at_reference)
    assert shared <= 1.3 * metrics.sphere_error(untextured.regions[0].table, table), shared
    assert np.isfinite(result.result.regions[0].table).all()
    result.retexture(result.result.regions[0])  # under its settings: the photos' texture
    assert result.textures[0].map.stats["pattern"] == "photos and scan texture"
    assert result.textures[0].choice == choice
