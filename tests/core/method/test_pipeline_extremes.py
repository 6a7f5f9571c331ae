"""Numerical extremes of the array pipeline on the synthetic scene (no bpy).

Near-black and near-mirror materials and photos clipped at a white level must
give finite tables, candidates and KL scores, and a white level given to the
observations must remove exactly the clipped pixels that no other reason
removes. ``bench/extremes_bench.py`` runs the same cases on the bunny.
"""

import numpy as np
import pytest

from brdf_reconstruct.core.brdf import database, merl
from brdf_reconstruct.core.method import observations, pipeline
from testkit import synthetic

RES = 64
FAST = pipeline.PipelineSettings(n_samples=12, n_trials=2, seed=1)
LAMBERT_1E3 = {"name": "lambert_1e-3", "lobes": [{"type": "lambert", "albedo": [1e-3] * 3}]}
MIRROR = {"name": "silver_alpha_0.01",
          "lobes": [{"type": "ggx", "alpha": 0.01,
                     "fresnel": {"type": "conductor", "metal": "Ag"}}]}


def _scene():
    z = synthetic.height_field(RES)
    return synthetic.gbuffer_from_heights(z), synthetic.gbuffer_from_heights(
        synthetic.blunted(z, rng=2))


def _inputs(table, clip_level=None):
    """Photos (1 % noise) of the true height field under three lights, clipped at
    ``clip_level`` if given, with the blunted scan's G-buffers."""
    truth, scan = _scene()
    inputs = []
    for i in range(3):
        photo = synthetic.photo(table, truth, synthetic.LIGHTS[i], noise=0.01, rng=i)
        if clip_level is not None:
            photo = np.minimum(photo, clip_level)
        inputs.append(pipeline.PhotoInput(
            photo=photo, normal=scan.normal, position=scan.position,
            visibility=np.ones(scan.mask.shape), region=np.where(scan.mask, 0, -1),
            camera_center=scan.camera_center, light=synthetic.LIGHTS[i], name=f"photo{i}"))
    return inputs


def _assert_finite(result):
    ok = [r for r in result.regions if r.status == "ok"]
    assert ok
    for r in ok:
        assert np.all(np.isfinite(r.table)) and np.all(r.table >= 0)
        assert all(np.all(np.isfinite(c)) for c in r.candidates)
        assert np.all(np.isfinite(r.kl))


@pytest.mark.parametrize("spec", [LAMBERT_1E3, MIRROR], ids=["albedo_1e-3", "alpha_0.01"])
def test_extreme_materials_give_finite_tables(default_basis, spec):
    table = database.make_table(spec)
    result = pipeline.run(default_basis, _inputs(table), FAST)
    _assert_finite(result)
    if spec is LAMBERT_1E3:  # the level is found, not lost to a floor: rho ~ 3.2e-4 /sr
        valid = merl.valid_cells()
        ratio = result.regions[0].table.reshape(3, -1)[:, valid] / table.reshape(3, -1)[:, valid]
        assert 0.5 < np.median(ratio) < 2.0


def test_white_level_removes_exactly_the_clipped_pixels(default_basis):
    table = database.make_table(next(s for s in database.heldout_specs()
                                     if s["name"] == "heldout_glossy_plastic"))
    peak = max(p.photo.max() for p in _inputs(table))
    level = 0.2 * peak
    inputs = _inputs(table, clip_level=level)
    told = pipeline.PipelineSettings(
        n_samples=12, n_trials=2, seed=1,
        observation=observations.ObservationSettings(clip_level=level))
    samples, counts = pipeline.observe_photos(inputs, told)
    for p, c in zip(inputs, counts, strict=True):
        # every other removal is independent of the photo here (mask all, visibility 1)
        n = p.normal / np.linalg.norm(p.normal, axis=-1, keepdims=True)
        v = p.camera_center - p.position
        v /= np.linalg.norm(v, axis=-1, keepdims=True)
        light = p.light / np.linalg.norm(p.light)
        kept_otherwise = (n @ light >= 0.1) & (np.sum(n * v, axis=-1) >= 0.1)
        clipped = np.any(p.photo >= level, axis=-1)
        assert c["removed"]["saturated"] == np.count_nonzero(clipped & kept_otherwise) > 0
    assert np.all(samples.radiance < level)
    _assert_finite(pipeline.run(default_basis, inputs, told))


def test_clipped_highlight_turns_off_the_brightest_peak_rule_and_is_one_note(default_basis):
    """Eq. (2) puts the brightest pixel at theta_h = 0. With the highlight clipped and
    its core removed, the brightest pixel left sits at the white level on the
    highlight's edge, so the region skips Eq. (2) and says so; unclipped, it keeps it.
    The region's notes (the panel's and the batch run's) say that the peak's height
    was not photographed, with the count and share of its pixels clipped; unclipped,
    no such note."""
    table = database.make_table(next(s for s in database.heldout_specs()
                                     if s["name"] == "heldout_glossy_plastic"))
    level = 0.2 * max(p.photo.max() for p in _inputs(table))
    told = pipeline.PipelineSettings(
        n_samples=12, n_trials=2, seed=1,
        observation=observations.ObservationSettings(clip_level=level))
    clipped = pipeline.run(default_basis, _inputs(table, clip_level=level), told).regions[0]
    assert clipped.counts["saturated"] > 0
    assert clipped.skipped_assumptions.get("brightest") == [0]
    notes = pipeline.region_notes(clipped.summary())
    n, seen = clipped.counts["saturated"], clipped.counts["saturated"] + clipped.counts["observed"]
    assert len(notes) == 1 and notes[0].startswith(f"{n} of its pixels ({100 * n / seen:.1f} %")
    assert "peak's height was not photographed" in notes[0]
    not_told = pipeline.PipelineSettings(n_samples=12, n_trials=2, seed=1)
    plain = pipeline.run(default_basis, _inputs(table), not_told).regions[0]
    assert plain.counts["saturated"] == 0
    assert "brightest" not in plain.skipped_assumptions
    assert pipeline.region_notes(plain.summary()) == []

