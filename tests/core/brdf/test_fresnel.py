"""Fresnel terms (core.brdf.fresnel) against independent expectations: dielectric and
conductor reflectance, and the table of metals."""

import math

import numpy as np
import pytest

from brdf_reconstruct.core.brdf import fresnel


@pytest.mark.parametrize("eta", [1.33, 1.5, 2.4, 1.0 / 1.5])
def test_fresnel_dielectric_normal_incidence(eta):
    assert fresnel.fresnel_dielectric(1.0, eta) == pytest.approx(((eta - 1) / (eta + 1)) ** 2)


def test_fresnel_dielectric_grazing_is_one():
    assert fresnel.fresnel_dielectric(0.0, 1.5) == pytest.approx(1.0)
    assert fresnel.fresnel_dielectric(1e-7, 1.5) > 0.9999
    assert np.all(np.diff(fresnel.fresnel_dielectric(np.linspace(0, 1, 50), 1.5)) < 0)


def test_fresnel_dielectric_total_internal_reflection():
    eta = 1.0 / 1.5  # glass to air
    critical = math.asin(eta)
    beyond = np.cos(np.linspace(critical + 1e-6, math.pi / 2, 20))
    assert np.all(fresnel.fresnel_dielectric(beyond, eta) == 1.0)
    assert fresnel.fresnel_dielectric(math.cos(critical - 0.05), eta) < 1.0
    # A negative cosine means arriving from the dense side: same as inverting eta.
    c = np.linspace(0.05, 1.0, 20)
    np.testing.assert_allclose(fresnel.fresnel_dielectric(-c, 1.5),
                               fresnel.fresnel_dielectric(c, eta), rtol=1e-12)


def test_fresnel_dielectric_brewster_and_stokes():
    eta = 1.5
    theta_b = math.atan(eta)  # p-polarised reflectance vanishes; theta_i + theta_t = 90 deg
    assert fresnel.fresnel_dielectric(math.cos(theta_b), eta) == pytest.approx(
        0.5 * math.cos(2 * theta_b) ** 2)
    # Stokes: the reflectance is the same seen from either side along the refracted path.
    theta_i = np.linspace(0.0, 1.5, 30)
    theta_t = np.arcsin(np.sin(theta_i) / eta)
    np.testing.assert_allclose(fresnel.fresnel_dielectric(np.cos(theta_i), eta),
                               fresnel.fresnel_dielectric(np.cos(theta_t), 1 / eta), rtol=1e-12)


@pytest.mark.parametrize("metal", sorted(fresnel.METALS))
def test_fresnel_conductor_normal_incidence(metal):
    n, k = (np.array(v) for v in fresnel.METALS[metal])
    expected = ((n - 1) ** 2 + k**2) / ((n + 1) ** 2 + k**2)
    np.testing.assert_allclose(fresnel.fresnel_conductor(1.0, n, k), expected, rtol=1e-12)


def test_fresnel_conductor_matches_complex_amplitudes():
    rng = np.random.default_rng(3)
    c = rng.uniform(0.0, 1.0, 500)
    n, k = rng.uniform(0.05, 4.0, 500), rng.uniform(0.0, 8.0, 500)
    eta = n + 1j * k
    cos_t = np.sqrt(1.0 - (1.0 - c**2) / eta**2 + 0j)  # Im(eta cos_t) >= 0: decaying wave
    r_s = (c - eta * cos_t) / (c + eta * cos_t)
    r_p = (eta * c - cos_t) / (eta * c + cos_t)
    expected = 0.5 * (np.abs(r_s) ** 2 + np.abs(r_p) ** 2)
    np.testing.assert_allclose(fresnel.fresnel_conductor(c, n, k), expected, rtol=1e-9, atol=1e-12)


def test_fresnel_conductor_without_absorption_is_dielectric_and_grazing_is_one():
    c = np.linspace(0.0, 1.0, 101)
    np.testing.assert_allclose(fresnel.fresnel_conductor(c, 1.7, 0.0),
                               fresnel.fresnel_dielectric(c, 1.7), rtol=1e-10, atol=1e-14)
    assert np.allclose(fresnel.fresnel_conductor(0.0, np.array([0.2, 1.0, 3.0]), 3.0), 1.0)


def test_metals_table_is_complete_and_plausible():
    assert {"Al", "Au", "Cu", "Ag", "Cr", "Fe", "Ti", "Ni", "Pt"} <= set(fresnel.METALS)
    f0 = {m: fresnel.fresnel_conductor(1.0, *map(np.array, nk)) for m, nk in fresnel.METALS.items()}
    assert np.all(f0["Ag"] > 0.9) and np.all(f0["Al"] > 0.85)
    assert f0["Au"][0] > f0["Au"][2] + 0.3 and f0["Cu"][0] > f0["Cu"][2] + 0.3  # warm metals
    assert all(np.all((0.4 < f) & (f < 1.0)) for f in f0.values())
