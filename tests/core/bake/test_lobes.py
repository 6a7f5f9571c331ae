"""The Cycles-renderable lobe model (core.bake.lobes) against core.brdf.models, its
symmetries and its parameters (no bpy here; the model is checked against Cycles
renders in tests/blender/test_material.py, its fit in test_fitting.py)."""

from __future__ import annotations

import json

import numpy as np
import pytest

from brdf_reconstruct.core.bake import lobes
from brdf_reconstruct.core.brdf import merl, models


def _unit(v):
    v = np.asarray(v, dtype=np.float64)
    return v / np.linalg.norm(v, axis=-1, keepdims=True)


def _pairs(n, seed=0):
    rng = np.random.default_rng(seed)
    l = _unit(rng.normal(size=(n, 3)))
    v = _unit(rng.normal(size=(n, 3)))
    l[:, 2] = np.abs(l[:, 2])
    v[:, 2] = np.abs(v[:, 2])
    return l, v


_params = lobes.LobeParams.build


# A material of every kind of term the model has, for the round trips.
FULL = _params(diffuse=(0.2, 0.3, 0.1),
               lobes=(("ggx", (0.5, 0.4, 0.3), 0.3, 0.02),
                      ("beckmann", (0.1, 0.1, 0.2), 0.1, 0.3)),
               sheen=(0.1, 0.05, 0.05), sigma=0.5)


def test_ggx_lobe_is_models_ggx_without_fresnel():
    # core.brdf.models: height-correlated Smith GGX; Schlick with f0 = 1 is F = 1.
    l, v = _pairs(2000)
    color = [0.7, 0.5, 0.2]
    for alpha in (0.01, 0.2, 1.0):
        spec = {"name": "g", "lobes": [{"type": "ggx", "alpha": alpha, "weight": color,
                                        "fresnel": {"type": "schlick", "f0": 1.0}}]}
        p = _params(lobes=(("ggx", color, 0.0, alpha),))
        np.testing.assert_allclose(lobes.evaluate(p, l, v), models.evaluate(spec, l, v),
                                   rtol=1e-10, atol=1e-12)


def test_grazing_term_is_schlick_with_f0_zero():
    l, v = _pairs(2000, seed=1)
    spec = {"name": "g", "lobes": [{"type": "ggx", "alpha": 0.3,
                                    "fresnel": {"type": "schlick", "f0": 0.0}}]}
    p = _params(lobes=(("ggx", (0.0, 0.0, 0.0), 1.0, 0.3),))
    np.testing.assert_allclose(lobes.evaluate(p, l, v), models.evaluate(spec, l, v),
                               rtol=1e-10, atol=1e-12)


def test_beckmann_lobe_close_to_exact_smith():
    # Cycles' Beckmann Lambda is Walter's rational fit of the exact (erf) one in
    # core.brdf.models: the two agree to well under 1 % where the lobe has energy.
    l, v = _pairs(20000, seed=2)
    for alpha in (0.05, 0.3):
        spec = {"name": "b", "lobes": [{"type": "beckmann", "alpha": alpha,
                                        "fresnel": {"type": "schlick", "f0": 1.0}}]}
        ours = lobes.evaluate(_params(lobes=(("beckmann", (1, 1, 1), 0.0, alpha),)), l, v)
        exact = models.evaluate(spec, l, v)
        w = l[:, 2:] * v[:, 2:]  # energy in an image
        assert np.sum(np.abs(ours - exact) * w) / np.sum(exact * w) < 5e-3


def test_lambert_and_horizon():
    l, v = _pairs(100, seed=3)
    p = _params(diffuse=(0.5, 0.25, 0.1))
    np.testing.assert_allclose(lobes.evaluate(p, l, v),
                               np.tile(np.array([0.5, 0.25, 0.1]) / np.pi, (100, 1)))
    below = l * np.array([1.0, 1.0, -1.0])
    assert np.all(lobes.evaluate(FULL, below, v) == 0.0)
    assert np.all(lobes.evaluate(FULL, l, below) == 0.0)


def test_reciprocal_finite_and_dtype():
    l, v = _pairs(5000, seed=4)
    a = lobes.evaluate(FULL, l, v)
    np.testing.assert_allclose(a, lobes.evaluate(FULL, v, l), rtol=1e-12)
    assert np.all(np.isfinite(a)) and np.all(a >= 0.0)
    b = lobes.evaluate(FULL, l.astype(np.float32), v.astype(np.float32))
    assert b.dtype == np.float64
    np.testing.assert_allclose(b, a, rtol=1e-4, atol=1e-6)


def test_velvet_is_zero_at_the_mirror_direction_and_peaks_at_grazing_half_vector():
    p = _params(sheen=(1.0, 1.0, 1.0), sigma=0.4)
    n = np.array([[0.0, 0.0, 1.0]])
    assert np.all(lobes.evaluate(p, n, n) == 0.0)  # n.h = 1: Cycles returns 0
    # Half vector tilting away from n: velvet rises (D ~ exp(-cot^2 / sigma^2)).
    tilts = np.radians([10.0, 30.0, 50.0])
    l, v = merl.dirs_from_half_diff(tilts, np.radians(20.0), np.pi / 2)
    values = lobes.evaluate(p, l, v)[:, 0]
    assert np.all(np.diff(values) > 0.0)


def test_params_dict_round_trip():
    d = FULL.to_dict()
    assert json.loads(json.dumps(d)) == d
    back = lobes.LobeParams.from_dict(d)
    l, v = _pairs(500, seed=5)
    np.testing.assert_array_equal(lobes.evaluate(back, l, v), lobes.evaluate(FULL, l, v))
    np.testing.assert_array_equal(lobes.evaluate(d, l, v), lobes.evaluate(FULL, l, v))
    with pytest.raises(ValueError, match="distribution"):
        _params(lobes=(("phong", (1, 1, 1), 0.0, 0.1),))


# ------------------------------------------------------- blocks and width-free parts
def _ggx_inline(g, alpha):
    """Geometry.ggx as written before its width-free parts were kept."""
    a2 = alpha * alpha
    c2 = np.minimum(g.cos_h * g.cos_h, 1.0)
    t = (1.0 - c2) + a2 * c2
    d = a2 * lobes.INV_PI / (t * t)
    cl, cv = g.cos_l, g.cos_v
    mu_l = np.sqrt(cl * cl + a2 * (1.0 - cl * cl))
    mu_v = np.sqrt(cv * cv + a2 * (1.0 - cv * cv))
    return d * 0.5 / (cv * mu_l + cl * mu_v)


def _ggx_dlog_inline(g, alpha):
    a2 = alpha * alpha
    c2 = np.minimum(g.cos_h * g.cos_h, 1.0)
    t = (1.0 - c2) + a2 * c2
    cl, cv = g.cos_l, g.cos_v
    s_l, s_v = 1.0 - cl * cl, 1.0 - cv * cv
    mu_l = np.sqrt(cl * cl + a2 * s_l)
    mu_v = np.sqrt(cv * cv + a2 * s_v)
    den = cv * mu_l + cl * mu_v
    shape = a2 * lobes.INV_PI / (t * t) * 0.5 / den
    dlog_d = 2.0 - 4.0 * a2 * c2 / t
    dlog_v = -(cv * a2 * s_l / mu_l + cl * a2 * s_v / mu_v) / den
    return shape * (dlog_d + dlog_v)


def _beckmann_inline(g, alpha, derivative):
    a2 = alpha * alpha
    c2 = np.clip(g.cos_h * g.cos_h, 1e-300, 1.0)
    tan2 = (1.0 - c2) / c2
    d = np.exp(-tan2 / a2) / (np.pi * a2 * c2 * c2)
    lam, dlam = [], []
    for cos in (g.cos_l, g.cos_v):
        t2 = a2 * np.maximum(1.0 / (cos * cos) - 1.0, 0.0)
        zero = t2 < 0.39
        x = 1.0 / np.sqrt(np.where(zero, 1.0, t2))
        num = (0.396 * x - 1.259) * x + 1.0
        den = (2.181 * x + 3.535) * x
        lam.append(np.where(zero, 0.0, num / den))
        if derivative:
            dl_dx = ((0.792 * x - 1.259) * den - num * (4.362 * x + 3.535)) / (den * den)
            dlam.append(np.where(zero, 0.0, -x * dl_dx))
    g2 = 1.0 / (1.0 + lam[0] + lam[1])
    shape = d * g2 / (4.0 * g.cos_l * g.cos_v)
    if not derivative:
        return shape
    return shape * (2.0 * tan2 / a2 - 2.0 - (dlam[0] + dlam[1]) * g2)


def test_lobes_with_kept_width_free_parts_equal_the_inline_formulas():
    l, v = _pairs(20_000, seed=4)
    g = lobes.Geometry(l, v)
    for alpha in (1e-3, 0.02, 0.3, 1.0, np.float64(0.13)):
        np.testing.assert_array_equal(g.ggx(alpha), _ggx_inline(g, alpha))
        np.testing.assert_array_equal(g.ggx_dlog(alpha), _ggx_dlog_inline(g, alpha))
        np.testing.assert_array_equal(g.beckmann(alpha), _beckmann_inline(g, alpha, False))
        np.testing.assert_array_equal(g.beckmann_dlog(alpha), _beckmann_inline(g, alpha, True))


def test_evaluate_in_blocks_and_tabulate_equal_one_pass():
    """evaluate works in blocks of rows and tabulate in blocks of the grid: the same
    values as evaluating each row on its own and scattering them into the table."""
    rng = np.random.default_rng(2)
    l, v = _unit(rng.normal(size=(2, 80_000, 3)))  # some below the horizon
    whole = lobes.evaluate(FULL, l, v)
    pieces = np.concatenate([lobes.evaluate(FULL, l[i:i + 777], v[i:i + 777])
                             for i in range(0, len(l), 777)])
    np.testing.assert_array_equal(whole, pieces)
    wi, wo = merl.cell_directions()
    valid = merl.valid_cells()
    table = np.full((3, merl.N_CELLS), np.nan)
    table[:, valid] = lobes.evaluate(FULL, wi[valid], wo[valid]).T
    np.testing.assert_array_equal(lobes.tabulate(FULL), table.reshape(3, *merl.SHAPE))


def test_geometry_rounds_norm_and_dot_as_numpy_does():
    """Geometry writes |l + v| and l.(l + v) out per component; they must round as
    np.linalg.norm(axis=1) and np.einsum do (if numpy changes that, this flags it)."""
    rng = np.random.default_rng(5)
    l, v = _unit(rng.normal(size=(2, 50_000, 3)))
    g = lobes.Geometry(l, v)
    h = l + v
    norm = np.linalg.norm(h, axis=1)
    ok = norm > 0.0
    cos_h = np.clip(np.divide(h[:, 2], norm, out=np.ones_like(norm), where=ok), 0.0, 1.0)
    cos_d = np.clip(np.divide(np.einsum("ij,ij->i", l, h), norm, out=np.zeros_like(norm),
                              where=ok), 0.0, 1.0)
    np.testing.assert_array_equal(g.cos_h, cos_h)
    np.testing.assert_array_equal(g.cos_d, cos_d)
    np.testing.assert_array_equal(g.schlick, (1.0 - cos_d) ** 5)
    np.testing.assert_array_equal(g.cos_l, l[:, 2])
