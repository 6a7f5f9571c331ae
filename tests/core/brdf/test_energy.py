"""Directional albedo of tabulated BRDFs (core.brdf.energy) against analytic values:
a Lambert table reflects its albedo at every view angle, a table with unmeasured or
infinite cells still gives a finite answer, and a table twice a physical one
reflects twice as much, and a mirror-like lobe is integrated, not missed."""

from __future__ import annotations

import numpy as np
import pytest

from brdf_reconstruct.core.brdf import database, energy, merl

ALBEDO = np.array([0.2, 0.5, 0.8])


def _lambert():
    """(3, 90, 90, 180) a Lambert table of albedo ALBEDO: rho = albedo / pi."""
    return np.broadcast_to((ALBEDO / np.pi)[:, None, None, None],
                           (3, 90, 90, 180)).astype(np.float64).copy()


def test_a_lambert_table_reflects_its_albedo_at_every_view_angle():
    # the integral of (albedo / pi) cos(theta_l) over the hemisphere is the albedo;
    # the quadrature runs over half vectors, so this checks its Jacobian 4 (v.h)
    # and its horizon cut at every view angle up to 80 degrees
    got = energy.directional_albedo(_lambert(), energy.CHECK_ANGLES_DEG)
    assert got.shape == (len(energy.CHECK_ANGLES_DEG), 3)
    np.testing.assert_allclose(got, np.tile(ALBEDO, (len(got), 1)), rtol=0.01)
    assert energy.largest_albedo(_lambert()) == pytest.approx(0.8, rel=0.01)


def test_a_table_reflecting_more_than_it_receives_is_found():
    # the same Lambert table at 2 / 0.8 times its level: 2 at every angle, above 1
    scaled = _lambert() * (2.0 / 0.8)
    assert energy.largest_albedo(scaled) == pytest.approx(2.0, rel=0.01)


def test_unmeasured_and_infinite_cells_give_a_finite_albedo():
    table = _lambert()
    table[:, 40:50] = np.nan  # a band of theta_h unmeasured: filled from neighbours
    table[:, 0, 0, 0] = np.inf  # one infinite cell counts as nothing
    got = energy.directional_albedo(table, [0.0, 45.0, 80.0])
    assert np.isfinite(got).all()
    np.testing.assert_allclose(got, np.tile(ALBEDO, (3, 1)), rtol=0.02)


def test_float32_table_gives_the_float64_albedo():
    table = _lambert()
    np.testing.assert_allclose(energy.directional_albedo(table.astype(np.float32), [30.0]),
                               energy.directional_albedo(table, [30.0]), rtol=1e-6)


def test_fill_is_not_done_on_the_callers_table():
    table = _lambert()
    table[:, 10] = np.nan
    table[:, 0, 0, 0] = np.inf
    before = table.copy()
    energy.directional_albedo(table, [0.0])
    np.testing.assert_array_equal(table, before)  # NaN and Inf cells where they were


def test_a_mirror_like_lobe_is_integrated_not_missed():
    # GGX at alpha 0.02 with a Fresnel of 1: its peak is about 10^4 times the level
    # of a white Lambert surface's, and it reflects all the light it receives but
    # its shadowing (test_models: > 0.97 at alpha 0.1); the quadrature over half
    # vectors spaced as the table's theta_h bins finds it to 1 %, up to 80 degrees
    table = database.make_table({"name": "mirror", "lobes": [
        {"type": "ggx", "alpha": 0.02, "fresnel": {"type": "schlick", "f0": 1.0}}]})
    assert np.nanmax(table) > 1e4 / np.pi
    got = energy.directional_albedo(table, energy.CHECK_ANGLES_DEG)
    np.testing.assert_allclose(got, 1.0, atol=0.01)


def test_the_albedo_quadrature_is_the_directional_albedo():
    """energy.albedo_quadrature as a linear map of the cells gives
    energy.directional_albedo of the same quadrature (reference value)."""
    spec = {s["name"]: s for s in database.heldout_specs()}["heldout_glossy_plastic"]
    table = merl.fill_unmeasured(database.make_table(spec))
    index, weights = energy.albedo_quadrature(n_theta=40, n_phi=40)
    got = weights @ table.reshape(3, -1)[:, index].T
    want = energy.directional_albedo(table, energy.CHECK_ANGLES_DEG, 40, 40)
    np.testing.assert_allclose(got, want, rtol=1e-12, atol=1e-15)
    assert len(np.unique(index)) == len(index)
