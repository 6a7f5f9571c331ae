"""The built-in analytic BRDF database: coverage, determinism, tables, fingerprint."""

from __future__ import annotations

import copy
import json

import numpy as np
import pytest

from brdf_reconstruct.core.brdf import database, merl, models
from brdf_reconstruct.core.brdf.fresnel import METALS


@pytest.fixture(scope="module")
def training():
    return database.training_specs()


@pytest.fixture(scope="module")
def heldout():
    return database.heldout_specs()


def _lobes(specs):
    for spec in specs:
        yield from ((spec, lobe) for lobe in spec["lobes"])


def _without_name(spec):
    return {k: v for k, v in spec.items() if k != "name"}


def test_training_set_is_large_valid_json_with_unique_names(training):
    assert len(training) >= 120
    names = [s["name"] for s in training]
    assert len(set(names)) == len(names)
    for spec in training:
        models.validate_spec(spec)
    assert json.loads(json.dumps(training)) == training  # plain JSON data only


def test_training_set_is_deterministic(training):
    assert database.training_specs() == training
    assert database.heldout_specs() == database.heldout_specs()


def test_training_set_covers_the_material_families(training):
    categories = {s["category"] for s in training}
    assert {"lambert", "oren_nayar", "plastic", "metal", "metal_tinted", "paint", "fabric",
            "mixture"} <= categories
    metals = {lobe["fresnel"].get("metal") for _, lobe in _lobes(training) if "fresnel" in lobe}
    assert set(METALS) <= metals
    types = {lobe["type"] for _, lobe in _lobes(training)}
    assert types == set(models.LOBE_TYPES)
    assert any("coat" in s for s in training)


def test_training_albedo_spans_near_black_to_white(training):
    albedos = [np.max(lobe["albedo"]) for _, lobe in _lobes(training) if "albedo" in lobe]
    assert min(albedos) <= 2e-3 and max(albedos) >= 0.85
    # and not only at the pinned extremes: every decade in between is populated
    for lo, hi in [(1e-3, 1e-2), (1e-2, 1e-1), (1e-1, 1.0)]:
        assert sum(lo <= a < hi for a in albedos) >= 5


def test_training_roughness_spans_matte_to_mirror(training):
    alphas = [lobe["alpha"] for _, lobe in _lobes(training) if "alpha" in lobe]
    alphas += [s["coat"]["alpha"] for s in training if "coat" in s]
    assert min(alphas) <= 0.007 and max(alphas) >= 0.7
    near_mirror_metals = {lobe["fresnel"]["metal"] for _, lobe in _lobes(training)
                          if lobe.get("fresnel", {}).get("metal") and lobe["alpha"] <= 0.03}
    assert near_mirror_metals == set(METALS)


def test_heldout_set_is_disjoint_from_training(training, heldout):
    assert len(heldout) >= 8
    names = [s["name"] for s in heldout]
    assert len(set(names)) == len(names)
    assert all(n.startswith("heldout_") for n in names)
    assert not set(names) & {s["name"] for s in training}
    bodies = [_without_name(s) for s in training]
    for spec in heldout:
        models.validate_spec(spec)
        assert _without_name(spec) not in bodies, spec["name"]


def test_heldout_set_covers_the_required_cases(heldout):
    by_name = {s["name"]: s for s in heldout}
    mirror = [lobe for s in heldout for lobe in s["lobes"]
              if lobe.get("fresnel", {}).get("metal") in ("Ag", "Al")
              and 0.01 <= lobe["alpha"] <= 0.02]
    assert mirror
    black = by_name["heldout_near_black"]["lobes"]
    assert max(black[0]["albedo"]) < 2e-3 and black[1]["fresnel"]["type"] == "dielectric"
    assert by_name["heldout_gold_medium"]["lobes"][0]["fresnel"]["metal"] == "Au"
    assert {"plastic", "metal", "fabric", "paint", "lambert"} <= {s["category"] for s in heldout}


def test_make_table_nan_exactly_where_cells_are_invalid():
    spec = next(s for s in database.heldout_specs() if s["name"] == "heldout_coated_paint")
    table = database.make_table(spec)
    assert table.shape == (3, *merl.SHAPE) and table.dtype == np.float64
    valid = merl.valid_cells().reshape(merl.SHAPE)
    assert np.array_equal(np.isnan(table), np.broadcast_to(~valid, table.shape))
    measured = table[:, valid]
    assert np.all(np.isfinite(measured)) and np.all(measured >= 0)
    # Same values as evaluating the model directly, in the table's C order, with
    # Fresnel and the distributions at the cells' theta_d and theta_h bin centres
    # (test_models checks that this equals the plain evaluation to rounding).
    wi, wo = merl.cell_directions()
    cells = np.flatnonzero(valid.ravel())[::9973]
    bins = np.indices(merl.SHAPE).reshape(3, -1)[:, cells]
    centre = (np.arange(90) + 0.5) / 90
    levels = {"cos_h": (np.cos(centre**2 * np.pi / 2), bins[0]),
              "cos_d": (np.cos(centre * np.pi / 2), bins[1])}
    np.testing.assert_array_equal(
        table.reshape(3, -1)[:, cells].T,
        models.evaluate(spec, wi[cells], wo[cells], levels=levels))
    np.testing.assert_allclose(table.reshape(3, -1)[:, cells].T,
                               models.evaluate(spec, wi[cells], wo[cells]), rtol=1e-9)


def test_make_table_of_lambert_is_constant():
    table = database.make_table({"name": "grey", "lobes": [{"type": "lambert", "albedo": 0.5}]})
    np.testing.assert_allclose(table[:, merl.valid_cells().reshape(merl.SHAPE)], 0.5 / np.pi,
                               rtol=1e-15)


def test_fingerprint_is_stable_and_tracks_specs(training):
    fp = database.database_fingerprint(training)
    assert fp == database.database_fingerprint(copy.deepcopy(training))
    assert len(fp) == 32 and int(fp, 16) >= 0
    changed = copy.deepcopy(training)
    changed[7]["lobes"][0]["albedo"][0] += 1e-4
    assert database.database_fingerprint(changed) != fp
    assert database.database_fingerprint(training[:-1]) != fp
