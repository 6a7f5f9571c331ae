"""The fit of the lobe model (core.bake.fitting) to tabulated BRDFs: exact cases, the
held-out materials' error bounds, damaged and extreme tables (no bpy)."""

from __future__ import annotations

import json

import numpy as np
import pytest

from brdf_reconstruct.core.bake import fitting, lobes
from brdf_reconstruct.core.brdf import database, merl, metrics, render

_params = lobes.LobeParams.build


# A material of every kind of term the model has (as in test_lobes.py).
FULL = _params(diffuse=(0.2, 0.3, 0.1),
               lobes=(("ggx", (0.5, 0.4, 0.3), 0.3, 0.02),
                      ("beckmann", (0.1, 0.1, 0.2), 0.1, 0.3)),
               sheen=(0.1, 0.05, 0.05), sigma=0.5)


def _lambert_spec(albedo):
    return {"name": "lambert", "lobes": [{"type": "lambert", "albedo": list(albedo)}]}


@pytest.fixture(scope="module")
def lambert_table():
    return database.make_table(_lambert_spec([0.6, 0.35, 0.1]))


@pytest.fixture(scope="module")
def plastic_table():
    spec = {"name": "plastic", "lobes": [
        {"type": "lambert", "albedo": [0.3, 0.1, 0.05]},
        {"type": "ggx", "alpha": 0.08, "fresnel": {"type": "dielectric", "eta": 1.5}}]}
    return database.make_table(spec)


def test_lambert_table_gives_exact_kd(lambert_table):
    fit = fitting.fit(lambert_table)
    np.testing.assert_allclose(fit.params.diffuse, [0.6, 0.35, 0.1], atol=1e-3)
    assert fit.errors["log_rmse"] < 1e-4
    assert max(fit.errors["sphere_rel_rmse_lights"]) < 1e-3


def test_own_model_table_is_recovered():
    fit = fitting.fit(lobes.tabulate(FULL), n_lobes=2, sheen=True)
    p = fit.params
    assert p.distributions == FULL.distributions
    np.testing.assert_allclose(p.alphas, FULL.alphas, rtol=0.02)
    np.testing.assert_allclose(p.diffuse, FULL.diffuse, rtol=0.02, atol=2e-3)
    np.testing.assert_allclose(p.colors, FULL.colors, rtol=0.03, atol=3e-3)
    np.testing.assert_allclose(p.grazing, FULL.grazing, atol=0.02)
    np.testing.assert_allclose(p.sheen, FULL.sheen, rtol=0.05, atol=3e-3)
    assert abs(p.sheen_sigma - FULL.sheen_sigma) < 0.03
    assert max(fit.errors["sphere_rel_rmse_lights"]) < 5e-3
    assert fit.errors["log_rmse"] < 2e-3


# Bounds on the 12 held-out materials, each measured (mean over the four
# ERROR_LIGHTS of the sphere relative RMSE; measured value in the comment) and
# set with margin for what the model cannot represent, not tuned to pass:
# - conductors are GGX/Beckmann lobes with a conductor Fresnel, which the lobe
#   colour plus the grey Schlick rise follows closely;
# - layered plastics darken their diffuse base by (1 - F(cos_l))(1 - F(cos_v)) and
#   use the exact dielectric Fresnel: neither is in the model;
# - fabrics have an Oren-Nayar base (the model's diffuse is Lambert) and a
#   Charlie sheen, whose shape the Ashikhmin velvet matches poorly: on
#   "random_fabric", a pure dark sheen, the bake is a known failure (~0.66).
HELDOUT_BOUNDS = {
    "heldout_silver_mirror": 0.01,  # 0.0005
    "heldout_aluminium_polished": 0.01,  # 0.003
    "heldout_gold_medium": 0.02,  # 0.004
    "heldout_random_copper": 0.02,  # 0.002 (Beckmann)
    "heldout_lambert_grey": 1e-3,  # 0.0000
    "heldout_near_black": 0.06,  # 0.029
    "heldout_coated_paint": 0.08,  # 0.037
    "heldout_random_plastic": 0.08,  # 0.042
    "heldout_glossy_plastic": 0.12,  # 0.064
    "heldout_rough_plastic": 0.15,  # 0.089
    "heldout_fabric": 0.30,  # 0.22
    "heldout_random_fabric": 0.75,  # 0.66
}


def test_heldout_bounds_cover_every_heldout():
    assert set(HELDOUT_BOUNDS) == {s["name"] for s in database.heldout_specs()}


@pytest.mark.parametrize("name", sorted(HELDOUT_BOUNDS))
def test_heldout_fit_error_bounded(heldout_tables, name):
    fit = fitting.fit(heldout_tables[name])
    e = fit.errors
    print(f"{name}: log_rmse {e['log_rmse']:.4f} sphere {e['sphere_rel_rmse']:.4f} "
          f"lights {np.round(e['sphere_rel_rmse_lights'], 4)} fit {fit.info['time_fit_s']:.2f}s")
    assert np.all(np.isfinite(e["sphere_rel_rmse_lights"])) and np.isfinite(e["log_rmse"])
    assert np.mean(e["sphere_rel_rmse_lights"]) < HELDOUT_BOUNDS[name]
    assert e["log_rmse"] < 0.1  # measured max 0.066 (glossy plastic)


def test_unmeasured_nan_inf_negative_cells_are_ignored(plastic_table):
    clean = fitting.fit(plastic_table, errors=False)
    damaged = plastic_table.copy()
    rng = np.random.default_rng(7)
    flat = damaged.reshape(3, -1)
    for value in (np.nan, np.inf, -1.0):
        cells = rng.choice(flat.shape[1], size=flat.shape[1] // 20, replace=False)
        flat[rng.integers(0, 3), cells] = value
    fit = fitting.fit(damaged)
    for name in ("diffuse", "colors", "grazing", "alphas", "sheen"):
        value = getattr(fit.params, name)
        assert np.all(np.isfinite(value))
        np.testing.assert_allclose(value, getattr(clean.params, name), rtol=0.05, atol=5e-3)
    assert all(np.isfinite(x) for x in fit.errors["sphere_rel_rmse_lights"])


def test_float32_and_channel_last_layouts(plastic_table):
    ref = fitting.fit(plastic_table, errors=False)
    for table in (plastic_table.astype(np.float32), np.moveaxis(plastic_table, 0, -1)):
        fit = fitting.fit(table, errors=False)
        np.testing.assert_allclose(fit.params.alphas, ref.params.alphas, rtol=1e-3)
        np.testing.assert_allclose(fit.params.diffuse, ref.params.diffuse, rtol=1e-3, atol=1e-6)


def _fit_errors_whole(params, table, resolution=64):
    """fit_errors as it was written before it looked the spheres' cells up once and
    filled only those: two whole tables filled, eight render_sphere calls."""
    t = fitting.clean_table(table)
    model = lobes.tabulate(params)
    log_rmse = metrics.brdf_log_rmse(model, t)
    t, model = merl.fill_unmeasured(t), merl.fill_unmeasured(model)
    per_light = [metrics.relative_rmse(render.render_sphere(model, light, resolution),
                                       render.render_sphere(t, light, resolution))
                 for light in fitting.ERROR_LIGHTS]
    return {"log_rmse": float(log_rmse), "sphere_rel_rmse": float(per_light[0]),
            "sphere_rel_rmse_lights": [float(e) for e in per_light]}


def test_fit_errors_equal_whole_table_spheres_bit_for_bit(plastic_table):
    damaged = plastic_table.copy()
    rng = np.random.default_rng(5)
    damaged[rng.random(damaged.shape) < 0.05] = np.nan
    damaged[0, 3, 10, 5], damaged[1, 4, 2, 2] = np.inf, -1.0
    for table, params in ((plastic_table, FULL), (damaged, FULL),
                          (np.moveaxis(plastic_table, 0, -1).astype(np.float32),
                           _params(diffuse=(0.3, 0.1, 0.05),
                                   lobes=(("ggx", (0.04, 0.04, 0.04), 0.5, 0.006),)))):
        assert fitting.fit_errors(params, table) == _fit_errors_whole(params, table)


def test_nnls_solves_shared_systems_once_with_the_same_result():
    """Problems whose labels agree on an active set share its system: solving it once
    for all of them gives each the solution it gets alone."""
    rng = np.random.default_rng(4)
    columns = rng.uniform(size=(500, 3, 12))  # per channel, 12 candidate columns
    grams = np.einsum("nci,ncj->cij", columns, columns)
    rhs = np.einsum("nci,nc->ci", columns, rng.uniform(size=(500, 3)))
    # problems: a constant column 0, two columns from 1..5 and one from 6..11
    pairs = np.array([(i, j) for i in range(1, 6) for j in range(i + 1, 6)])
    cols = np.concatenate([np.zeros((len(pairs) * 6, 1), dtype=int),
                           np.repeat(pairs, 6, axis=0),
                           np.tile(np.arange(6, 12), len(pairs))[:, None]], axis=1)
    gram = grams[:, cols[:, :, None], cols[:, None, :]].transpose(1, 0, 2, 3).reshape(-1, 4, 4)
    b = rhs[:, cols].transpose(1, 0, 2).reshape(-1, 4)
    labels = (cols[:, None, :] * 3 + np.arange(3)[None, :, None]).reshape(-1, 4)
    alone = fitting._nnls_from_gram(gram, b)
    shared = fitting._nnls_from_gram(gram, b, labels)
    for x, y in zip(alone, shared, strict=True):
        np.testing.assert_array_equal(x, y)


def test_nnls_from_gram_agrees_with_scipys_nnls_of_the_columns():
    """The exhaustive active-set NNLS over a batch of normal equations gives what an
    independent NNLS (scipy's Lawson-Hanson) gives on the columns themselves, on
    well- and ill-conditioned columns (near-parallel pairs, scales 1e-3 to 1e6; far
    below that the normal equations' absolute ridge, 1e-12, moves the minimum)."""
    from scipy.optimize import nnls

    rng = np.random.default_rng(11)
    A, y = [], []
    for i in range(120):
        a = rng.normal(size=(40, 5)) * np.exp(rng.uniform(-1, 1, 5))
        if i % 3 == 1:  # a near-parallel pair of columns
            a[:, 4] = a[:, 3] * (1 + 1e-4) + 1e-4 * rng.normal(size=40)
        a *= 10.0 ** rng.integers(-3, 7)
        A.append(a)
        y.append(a @ rng.normal(size=5) + 0.1 * np.abs(a).mean() * rng.normal(size=40))
    A, y = np.array(A), np.array(y)
    beta, val = fitting._nnls_from_gram(np.einsum("bni,bnj->bij", A, A),
                                        np.einsum("bni,bn->bi", A, y))
    for a, t, bt, v in zip(A, y, beta, val, strict=True):
        ref, res = nnls(a, t)
        # the same minimum of |A beta - y|^2 (= v + |y|^2), relative to |y|^2
        assert abs((v + t @ t) - res**2) <= 1e-7 * (t @ t)
        assert np.all(bt >= 0.0) and abs(np.sum((a @ bt - t) ** 2) - res**2) <= 1e-7 * (t @ t)


def test_nnls_skips_a_singular_active_set_instead_of_raising():
    """Two equal columns so large that the ridge vanishes in rounding: their joint
    system is singular. It is no candidate (LAPACK's solve raised LinAlgError on it);
    each column alone explains the target exactly."""
    gram = np.full((1, 2, 2), 1e20)
    rhs = np.full((1, 2), 1e20)
    beta, val = fitting._nnls_from_gram(gram, rhs)
    np.testing.assert_array_equal(beta, [[1.0, 0.0]])
    assert val[0] == -1e20 and np.all(np.isfinite(beta))


def test_clean_table_copies_unless_told_it_may_not(plastic_table):
    copy = fitting.clean_table(plastic_table)
    assert not np.may_share_memory(copy, plastic_table)
    assert fitting.clean_table(plastic_table, copy=False) is plastic_table  # already clean
    damaged = plastic_table.copy()
    damaged[0, 1, 2, 3] = -1.0
    cleaned = fitting.clean_table(damaged, copy=False)
    assert not np.may_share_memory(cleaned, damaged) and damaged[0, 1, 2, 3] == -1.0
    assert np.isnan(cleaned[0, 1, 2, 3])
    np.testing.assert_array_equal(cleaned, fitting.clean_table(damaged))


def test_deterministic(plastic_table):
    a = fitting.fit(plastic_table, n_lobes=1, errors=False)
    b = fitting.fit(plastic_table, n_lobes=1, errors=False)
    assert a.params.to_dict() == b.params.to_dict()
    assert set(a.errors) == {"fit_loss"}


def test_dark_diffuse_under_a_mirror_peak_is_recovered():
    # The log floor follows the median cell, so a diffuse 1e4 times darker than
    # the peak still steers the fit.
    spec = {"name": "m", "lobes": [
        {"type": "lambert", "albedo": [0.02, 0.01, 0.005]},
        {"type": "ggx", "alpha": 0.01, "fresnel": {"type": "dielectric", "eta": 1.5}}]}
    fit = fitting.fit(database.make_table(spec), errors=False)
    np.testing.assert_allclose(fit.params.diffuse, [0.02, 0.01, 0.005], rtol=0.1)
    assert fit.params.alphas[0] == pytest.approx(0.01, rel=0.05)


@pytest.mark.parametrize("alpha", [1e-4, 1e-3])
def test_mirror_extreme_is_finite(alpha):
    spec = {"name": "m", "lobes": [{"type": "ggx", "alpha": alpha,
                                    "fresnel": {"type": "conductor", "metal": "Ag"}}]}
    fit = fitting.fit(database.make_table(spec))
    d = fit.params.to_dict()
    assert np.all(np.isfinite(json.loads(json.dumps(d))["diffuse"]))
    assert np.all(np.isfinite(fit.params.colors)) and np.all(np.isfinite(fit.params.alphas))
    assert fit.params.alphas.min() >= lobes.ALPHA_MIN
    assert all(np.isfinite(x) for x in fit.errors["sphere_rel_rmse_lights"])


def test_near_black_and_black_are_finite(lambert_table):
    fit = fitting.fit(lambert_table * 1e-6, errors=False)
    np.testing.assert_allclose(fit.params.diffuse, np.array([0.6, 0.35, 0.1]) * 1e-6, rtol=1e-3)
    black = fitting.fit(np.where(np.isnan(lambert_table), np.nan, 0.0))
    for name in ("diffuse", "colors", "grazing", "sheen"):
        assert np.all(getattr(black.params, name) == 0.0)
    assert np.all(np.isfinite(black.params.alphas))
    assert black.errors["log_rmse"] == 0.0


def test_bad_input_is_a_clear_error(lambert_table):
    with pytest.raises(ValueError, match="shape"):
        fitting.fit(np.zeros((3, 90, 90)))
    with pytest.raises(ValueError, match="n_lobes"):
        fitting.fit(lambert_table, n_lobes=3)
    with pytest.raises(ValueError, match="no measured cell"):
        fitting.fit(np.full((3, *merl.SHAPE), np.nan))


def test_fewer_lobes_and_no_sheen(plastic_table):
    for n_lobes in (0, 1):
        fit = fitting.fit(plastic_table, n_lobes=n_lobes, sheen=False, errors=False)
        assert fit.params.alphas.shape == (n_lobes,)
        assert np.all(fit.params.sheen == 0.0)
    assert fitting.fit(plastic_table, n_lobes=1, sheen=False).errors["sphere_rel_rmse"] < 0.05
