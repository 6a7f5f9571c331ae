"""The rendered-sphere error used by the benchmarks (core.brdf.metrics.sphere_error)."""

import numpy as np
import pytest

from brdf_reconstruct.core.brdf import merl, metrics


def _lambert(albedo):
    return np.broadcast_to(np.asarray(albedo, float)[:, None, None, None] / np.pi,
                           (3, *merl.SHAPE)).copy()


def test_sphere_error_of_a_scaled_table_is_the_scale_offset():
    truth = _lambert([0.5, 0.4, 0.3])
    assert metrics.sphere_error(truth, truth) == 0.0
    # every pixel scales by 1.1 -> relative RMSE exactly 0.1, under every light
    assert np.isclose(metrics.sphere_error(1.1 * truth, truth), 0.1, rtol=1e-12)


def test_sphere_lights_are_20_60_100_degrees_from_the_view():
    angles = np.degrees(np.arccos(metrics.SPHERE_LIGHTS @ [0.0, 0.0, 1.0]))
    assert np.allclose(angles, [20.0, 60.0, 100.0])
    assert np.allclose(np.linalg.norm(metrics.SPHERE_LIGHTS, axis=1), 1.0)


def test_brdf_log_rmse_in_blocks_equals_the_whole_table_at_once():
    """brdf_log_rmse works in blocks of cells; the mean is the same to the last bit as
    the one-pass formula (same values, added in the same order)."""
    rng = np.random.default_rng(3)
    est = rng.lognormal(-1.0, 2.0, size=(3, *merl.SHAPE))
    ref = rng.lognormal(-1.0, 2.0, size=(3, *merl.SHAPE))
    ref[rng.random(ref.shape) < 0.1] = np.nan
    wi, wo = merl.cell_directions()
    c = np.clip(wi[:, 2] * wo[:, 2], 0.0, 1.0)
    for a, b in ((est, ref), (np.nan_to_num(ref), est), (est, est * 1.1)):
        fa, fb = a.reshape(3, -1), b.reshape(3, -1)
        keep = merl.valid_cells() & np.all(np.isfinite(fb), axis=0)
        d = np.log1p(fa[:, keep] * c[keep]) - np.log1p(fb[:, keep] * c[keep])
        assert metrics.brdf_log_rmse(a, b) == float(np.sqrt(np.mean(d**2)))


def test_log_rmse_at_every_cell_is_the_tables():
    """metrics.log_rmse_at over every cell, given the estimate's values there, is
    brdf_log_rmse of the tables (reference); over a subset it leaves out the same
    cells (below the horizon, unmeasured) as the one-pass formula over that subset."""
    rng = np.random.default_rng(4)
    est = rng.lognormal(-1.0, 2.0, size=(3, *merl.SHAPE))
    ref = rng.lognormal(-1.0, 2.0, size=(3, *merl.SHAPE))
    ref[rng.random(ref.shape) < 0.1] = np.nan
    every = np.arange(merl.N_CELLS)
    flat = est.reshape(3, -1)
    assert metrics.log_rmse_at(flat.T, ref, every) == pytest.approx(
        metrics.brdf_log_rmse(est, ref), rel=1e-12)
    some = np.sort(rng.choice(merl.N_CELLS, 50_000, replace=False))
    wi, wo = merl.cell_directions()
    fb = ref.reshape(3, -1)[:, some]
    keep = merl.valid_cells()[some] & np.all(np.isfinite(fb), axis=0)
    c = np.clip(wi[some, 2] * wo[some, 2], 0.0, 1.0)[keep]
    d = np.log1p(flat[:, some][:, keep] * c) - np.log1p(fb[:, keep] * c)
    assert metrics.log_rmse_at(flat[:, some].T, ref, some) == pytest.approx(
        float(np.sqrt(np.mean(d**2))), rel=1e-12)
