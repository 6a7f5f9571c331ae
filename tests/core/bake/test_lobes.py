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
