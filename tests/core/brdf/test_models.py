"""Analytic BRDF models (core.brdf.models) against independent expectations (the
Fresnel terms: test_fresnel.py)."""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy import integrate

from brdf_reconstruct.core.brdf import models


def _unit(v):
    v = np.asarray(v, dtype=np.float64)
    return v / np.linalg.norm(v, axis=-1, keepdims=True)


def _random_pairs(n, seed=0, upper=True):
    rng = np.random.default_rng(seed)
    wi = _unit(rng.normal(size=(n, 3)))
    wo = _unit(rng.normal(size=(n, 3)))
    if upper:
        wi[:, 2] = np.abs(wi[:, 2])
        wo[:, 2] = np.abs(wo[:, 2])
    return wi, wo


def _material(*lobes, coat=None):
    spec = {"name": "test", "lobes": list(lobes)}
    if coat is not None:
        spec["coat"] = coat
    return spec


LAMBERT = {"type": "lambert", "albedo": [0.2, 0.5, 0.8]}
OREN_NAYAR = {"type": "oren_nayar", "albedo": [0.7, 0.4, 0.3], "sigma": 0.6}
GGX_METAL = {"type": "ggx", "alpha": 0.2, "fresnel": {"type": "conductor", "metal": "Au"}}
BECKMANN_PLASTIC = {"type": "beckmann", "alpha": 0.15,
                    "fresnel": {"type": "dielectric", "eta": [1.45, 1.5, 1.55]}}
SCHLICK = {"type": "ggx", "alpha": 0.4, "fresnel": {"type": "schlick", "f0": [0.9, 0.6, 0.3]}}
SHEEN = {"type": "sheen", "color": [0.8, 0.7, 0.9], "roughness": 0.4}
COAT = {"distribution": "ggx", "alpha": 0.05, "eta": 1.5, "weight": 0.8}

ALL_MATERIALS = {
    "lambert": _material(LAMBERT),
    "oren_nayar": _material(OREN_NAYAR),
    "ggx_conductor": _material(GGX_METAL),
    "beckmann_dielectric": _material(BECKMANN_PLASTIC),
    "ggx_schlick": _material(SCHLICK),
    "sheen": _material(SHEEN),
    "coated_mixture": _material(dict(LAMBERT, weight=0.5), dict(GGX_METAL, weight=[0.2, 0.3, 0.4]),
                                coat=COAT),
    "beckmann_coat": _material(OREN_NAYAR, coat=dict(COAT, distribution="beckmann")),
}


def directional_albedo(spec, theta_i, n_mu=256, n_phi=256):
    """Integral of rho cos(theta_o) over the outgoing hemisphere, by quadrature.

    Gauss-Legendre in cos(theta_o), midpoint rule in phi_o. Returns (3,).
    """
    x, w = np.polynomial.legendre.leggauss(n_mu)
    mu, w_mu = 0.5 * (x + 1.0), 0.5 * w
    phi = (np.arange(n_phi) + 0.5) * (2.0 * np.pi / n_phi)
    m, p = np.meshgrid(mu, phi, indexing="ij")
    s = np.sqrt(1.0 - m * m)
    wo = np.stack([s * np.cos(p), s * np.sin(p), m], axis=-1).reshape(-1, 3)
    wi = np.tile([math.sin(theta_i), 0.0, math.cos(theta_i)], (wo.shape[0], 1))
    weights = np.repeat(w_mu, n_phi) * (2.0 * np.pi / n_phi) * wo[:, 2]
    return weights @ models.evaluate(spec, wi, wo)


# --- distributions --------------------------------------------------------------


@pytest.mark.parametrize("ndf", [models.ggx_ndf, models.beckmann_ndf])
@pytest.mark.parametrize("alpha", [0.05, 0.5])
def test_ndf_projected_area_is_one(ndf, alpha):
    def f(theta):
        return float(ndf(math.cos(theta), alpha)) * math.cos(theta) * math.sin(theta) * 2 * math.pi

    total = sum(integrate.quad(f, a, b, limit=200)[0]
                for a, b in [(0, 5 * alpha), (5 * alpha, math.pi / 2)])
    assert total == pytest.approx(1.0, rel=1e-6)


@pytest.mark.parametrize("roughness", [0.25, 0.5, 1.0])
def test_charlie_ndf_projected_area_is_one(roughness):
    def f(theta):
        return (float(models.charlie_ndf(math.cos(theta), roughness))
                * math.cos(theta) * math.sin(theta) * 2 * math.pi)

    assert integrate.quad(f, 0, math.pi / 2)[0] == pytest.approx(1.0, rel=1e-8)


@pytest.mark.parametrize("alpha", [0.01, 0.3, 1.0])
def test_smith_terms_match_lambda_from_the_textbook(alpha):
    # mu = cos (1 + 2 Lambda); Lambda from its definitions with math.erf (Beckmann)
    # and the closed form (GGX), a = 1 / (alpha tan(theta)).
    theta = np.linspace(0.01, 1.56, 60)
    c = np.cos(theta)
    a = 1.0 / (alpha * np.tan(theta))
    erf = np.array([math.erf(x) for x in a])
    lam_beckmann = 0.5 * (erf - 1.0) + np.exp(-a * a) / (2.0 * a * math.sqrt(math.pi))
    lam_ggx = 0.5 * (np.sqrt(1.0 + 1.0 / (a * a)) - 1.0)
    np.testing.assert_allclose(models._smith_mu(c, alpha, "beckmann"),
                               c * (1 + 2 * lam_beckmann), rtol=2e-6, atol=1e-9)
    np.testing.assert_allclose(models._smith_mu(c, alpha, "ggx"), c * (1 + 2 * lam_ggx),
                               rtol=1e-12)


# --- lobes -----------------------------------------------------------------------


def test_lambert_is_albedo_over_pi():
    wi, wo = _random_pairs(1000, seed=1)
    rho = models.evaluate(_material(LAMBERT), wi, wo)
    np.testing.assert_allclose(rho, np.tile(np.array(LAMBERT["albedo"]) / np.pi, (1000, 1)),
                               rtol=1e-15)


def test_oren_nayar_reduces_to_lambert_and_to_a_at_normal_light():
    wi, wo = _random_pairs(500, seed=2)
    smooth = _material(dict(OREN_NAYAR, sigma=0.0))
    lambert = _material(dict(LAMBERT, albedo=OREN_NAYAR["albedo"]))
    np.testing.assert_allclose(models.evaluate(smooth, wi, wo), models.evaluate(lambert, wi, wo),
                               rtol=1e-15)
    # Light along the normal: tan(beta) = 0, so only A = 1 - 0.5 s^2 / (s^2 + 0.33) is left.
    s2 = OREN_NAYAR["sigma"] ** 2
    normal = np.tile([0.0, 0.0, 1.0], (500, 1))
    rho = models.evaluate(_material(OREN_NAYAR), normal, wo)
    expected = (1 - 0.5 * s2 / (s2 + 0.33)) * np.array(OREN_NAYAR["albedo"]) / np.pi
    np.testing.assert_allclose(rho, np.tile(expected, (500, 1)), rtol=1e-14)


def test_ggx_white_furnace_closed_form_at_alpha_one():
    # alpha = 1: D = 1/pi and mu = 1, so with F = 1 and light along the normal
    # the albedo is the integral of mu/(1+mu) over [0, 1] = 1 - ln 2.
    spec = _material({"type": "ggx", "alpha": 1.0, "fresnel": {"type": "schlick", "f0": 1.0}})
    np.testing.assert_allclose(directional_albedo(spec, 0.0), 1 - math.log(2), rtol=1e-6)


@pytest.mark.parametrize("dist", ["ggx", "beckmann"])
def test_smooth_microfacet_reflects_almost_everything(dist):
    spec = _material({"type": dist, "alpha": 0.1, "fresnel": {"type": "schlick", "f0": 1.0}})
    assert np.all(directional_albedo(spec, 0.0) > 0.97)


def test_coat_over_black_is_a_dielectric_lobe_and_weight_zero_is_the_base():
    wi, wo = _random_pairs(2000, seed=4)
    coat_only = _material(dict(LAMBERT, albedo=0.0), coat=dict(COAT, weight=1.0))
    lobe = _material({"type": "ggx", "alpha": COAT["alpha"],
                      "fresnel": {"type": "dielectric", "eta": COAT["eta"]}})
    np.testing.assert_allclose(models.evaluate(coat_only, wi, wo),
                               models.evaluate(lobe, wi, wo), rtol=1e-13)
    no_coat = _material(OREN_NAYAR, coat=dict(COAT, weight=0.0))
    np.testing.assert_array_equal(models.evaluate(no_coat, wi, wo),
                                  models.evaluate(_material(OREN_NAYAR), wi, wo))


@pytest.mark.parametrize("name", sorted(ALL_MATERIALS))
def test_reciprocity(name):
    wi, wo = _random_pairs(5000, seed=5, upper=False)
    spec = ALL_MATERIALS[name]
    forward = models.evaluate(spec, wi, wo)
    np.testing.assert_allclose(forward, models.evaluate(spec, wo, wi), rtol=1e-12, atol=0)
    assert np.any(forward > 0)


@pytest.mark.parametrize("name", sorted(ALL_MATERIALS))
def test_zero_below_horizon_and_non_negative(name):
    wi, wo = _random_pairs(5000, seed=6, upper=False)
    rho = models.evaluate(ALL_MATERIALS[name], wi, wo)
    below = (wi[:, 2] <= 0) | (wo[:, 2] <= 0)
    assert np.all(rho[below] == 0.0)
    assert np.all(rho[~below] >= 0.0) and np.all(np.isfinite(rho))


ENERGY_CASES = {
    "white_lambert": _material({"type": "lambert", "albedo": 1.0}),
    "white_oren_nayar": _material({"type": "oren_nayar", "albedo": 1.0, "sigma": 1.2}),
    "white_plastic_layered": _material({"type": "lambert", "albedo": 0.95},
                                       coat={"distribution": "ggx", "alpha": 0.2, "eta": 1.8}),
    "white_plastic_rough_beckmann": _material(
        {"type": "lambert", "albedo": 0.95},
        coat={"distribution": "beckmann", "alpha": 0.8, "eta": 1.5}),
    "silver_ggx": _material({"type": "ggx", "alpha": 0.3,
                             "fresnel": {"type": "conductor", "metal": "Ag"}}),
    "aluminium_beckmann": _material({"type": "beckmann", "alpha": 0.5,
                                     "fresnel": {"type": "conductor", "metal": "Al"}}),
    "white_sheen_at_roughness_bound": _material(
        {"type": "sheen", "color": 1.0, "roughness": models.SHEEN_ROUGHNESS_MIN}),
}


@pytest.mark.parametrize("name", sorted(ENERGY_CASES))
def test_directional_albedo_at_most_one(name):
    for theta_deg in (0.0, 45.0, 75.0, 89.0):
        albedo = directional_albedo(ENERGY_CASES[name], math.radians(theta_deg))
        assert np.all(albedo <= 1.0 + 2e-3), (theta_deg, albedo)
        assert np.all(albedo > 0.0)
    if name == "white_lambert":  # also checks the quadrature itself
        np.testing.assert_allclose(albedo, 1.0, rtol=1e-10)


# --- degenerate inputs -----------------------------------------------------------


def _degenerate_pairs():
    z = np.array([0.0, 0.0, 1.0])
    grazing = np.array([1.0, 0.0, 0.0])
    nearly_opposite_i = _unit([1.0, 0.0, 1e-12])
    nearly_opposite_o = _unit([-1.0, 1e-15, 1e-12])
    wi = np.array([z, grazing, z, nearly_opposite_i, _unit([1, 0, 1e-300]), -z, _unit([1, 2, 3])])
    wo = np.array([z, z, grazing, nearly_opposite_o, _unit([-1, 0, 1e-300]), z, _unit([-1, -2, 3])])
    return wi, wo


@pytest.mark.parametrize("alpha", [1e-4, 1e-9, 0.5])
@pytest.mark.parametrize("name", sorted(ALL_MATERIALS))
def test_degenerate_directions_and_tiny_alpha_are_finite(name, alpha):
    spec = ALL_MATERIALS[name]
    spec = dict(spec, lobes=[dict(lobe, alpha=alpha) if "alpha" in lobe else lobe
                             for lobe in spec["lobes"]])
    if "coat" in spec:
        spec["coat"] = dict(spec["coat"], alpha=alpha)
    wi, wo = _degenerate_pairs()
    with np.errstate(divide="raise", over="raise", invalid="raise"):
        rho = models.evaluate(spec, wi, wo)
    assert rho.shape == (len(wi), 3) and np.all(np.isfinite(rho)) and np.all(rho >= 0)
    assert np.all(rho[1:3] == 0.0) and np.all(rho[5] == 0.0)  # a direction at or below 90 deg


def test_float32_input_gives_float64_output():
    wi, wo = _random_pairs(1000, seed=7)
    wi32, wo32 = wi.astype(np.float32), wo.astype(np.float32)
    spec = ALL_MATERIALS["coated_mixture"]
    rho = models.evaluate(spec, wi32, wo32)
    assert rho.dtype == np.float64 and np.all(np.isfinite(rho))
    np.testing.assert_array_equal(rho, models.evaluate(spec, wi32.astype(np.float64),
                                                        wo32.astype(np.float64)))


def test_empty_input_and_json_round_trip():
    import json

    empty = np.zeros((0, 3))
    assert models.evaluate(ALL_MATERIALS["sheen"], empty, empty).shape == (0, 3)
    wi, wo = _random_pairs(100, seed=8)
    spec = ALL_MATERIALS["coated_mixture"]
    np.testing.assert_array_equal(models.evaluate(json.loads(json.dumps(spec)), wi, wo),
                                  models.evaluate(spec, wi, wo))


# --- validation at the edge ------------------------------------------------------


@pytest.mark.parametrize(("spec", "message"), [
    ({"lobes": [LAMBERT]}, r"spec\['name'\]"),
    ({"name": "x", "lobes": [LAMBERT], "colour": 1}, r"spec\['colour'\]: unknown key"),
    ({"name": "x", "lobes": [{"type": "phong"}]}, r"spec\['lobes'\]\[0\]\['type'\]"),
    ({"name": "x", "lobes": [LAMBERT, dict(GGX_METAL, alpha=-0.1)]},
     r"spec\['lobes'\]\[1\]\['alpha'\]"),
    ({"name": "x", "lobes": [dict(GGX_METAL, fresnel={"type": "conductor", "metal": "Zz"})]},
     r"\['fresnel'\]\['metal'\]"),
    ({"name": "x", "lobes": [dict(LAMBERT, albedo=[0.1, 0.2])]}, r"\['albedo'\]"),
    ({"name": "x", "lobes": [dict(LAMBERT, sigma=0.3)]}, r"\['sigma'\]: unknown key"),
    ({"name": "x", "lobes": [dict(SHEEN, roughness=0.1)]}, r"\['roughness'\]"),
    ({"name": "x", "lobes": [LAMBERT], "coat": dict(COAT, distribution="phong")},
     r"spec\['coat'\]\['distribution'\]"),
    ({"name": "x", "lobes": []}, r"spec\['lobes'\]"),
])
def test_bad_spec_names_the_bad_key(spec, message):
    wi, wo = _random_pairs(3)
    with pytest.raises(ValueError, match=message):
        models.evaluate(spec, wi, wo)
    with pytest.raises(ValueError, match=message):
        models.validate_spec(spec)


def test_bad_directions_name_the_argument():
    wi, wo = _random_pairs(3)
    with pytest.raises(ValueError, match="wi"):
        models.evaluate(ALL_MATERIALS["lambert"], wi[:, :2], wo)
    bad = wo.copy()
    bad[0, 0] = np.nan
    with pytest.raises(ValueError, match="wo"):
        models.evaluate(ALL_MATERIALS["lambert"], wi, bad)


@pytest.mark.parametrize("name", sorted(ALL_MATERIALS))
def test_terms_on_grid_levels_equal_the_plain_evaluation(name):
    # Pairs built from half/difference angles with theta_h on 5 and theta_d on 7
    # levels (as on the MERL grid), some below the horizon: Fresnel and the
    # distributions evaluated once per level and gathered must give the per-pair
    # result to rounding, and zero where invalid.
    from brdf_reconstruct.core.brdf import merl

    rng = np.random.default_rng(3)
    n = 5000
    theta_h_levels = np.linspace(0.0, 1.5, 5)
    theta_d_levels = np.linspace(0.05, 1.55, 7)
    ih, id_ = rng.integers(0, 5, n), rng.integers(0, 7, n)
    wi, wo = merl.dirs_from_half_diff(theta_h_levels[ih], theta_d_levels[id_],
                                      rng.uniform(0, np.pi, n))
    assert np.any(wi[:, 2] <= 0) and np.any(wi[:, 2] > 0)
    plain = models.evaluate(ALL_MATERIALS[name], wi, wo)
    for levels in ({"cos_d": (np.cos(theta_d_levels), id_)},
                   {"cos_h": (np.cos(theta_h_levels), ih)},
                   {"cos_d": (np.cos(theta_d_levels), id_),
                    "cos_h": (np.cos(theta_h_levels), ih)}):
        # to rounding: the plain path recomputes the cosines from the rounded
        # directions (and clamps cos_i, cos_o at 1e-9), which moves a sharp peak's
        # value by up to 1e-10 relative here (the levels' own check allows 1e-9), and
        # a far tail's underflow by 1e-12 of the peak
        np.testing.assert_allclose(models.evaluate(ALL_MATERIALS[name], wi, wo, levels=levels),
                                   plain, rtol=1e-9, atol=1e-12 * plain.max())


def test_wrong_levels_are_refused():
    from brdf_reconstruct.core.brdf import merl

    wi, wo = merl.dirs_from_half_diff(np.full(4, 0.3), np.full(4, 0.6), np.full(4, 1.0))
    spec = ALL_MATERIALS["ggx_conductor"]
    with pytest.raises(ValueError, match="cos_d is not its level"):
        models.evaluate(spec, wi, wo, levels={"cos_d": (np.cos([0.6, 0.7]), np.ones(4, int))})
    with pytest.raises(ValueError, match="cos_h is not its level"):
        models.evaluate(spec, wi, wo, levels={"cos_h": (np.cos([0.3, 0.4]), np.ones(4, int))})
    with pytest.raises(ValueError, match="out of range"):
        models.evaluate(spec, wi, wo, levels={"cos_d": (np.cos([0.6]), np.ones(4, int))})
    with pytest.raises(ValueError, match="integers"):
        models.evaluate(spec, wi, wo, levels={"cos_d": (np.cos([0.6]), np.zeros(4))})
    with pytest.raises(ValueError, match="unknown key"):
        models.evaluate(spec, wi, wo, levels={"theta": (np.cos([0.6]), np.zeros(4, int))})
