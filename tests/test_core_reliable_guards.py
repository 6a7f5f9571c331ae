"""The checks of the paper's assumptions before applying them (ReliableSettings
``peak_max_angle`` and ``monotonicity_max_fraction``), on numpy scenes."""

import numpy as np
import pytest

from brdf_reconstruct.core.brdf import database
from brdf_reconstruct.core.method import observations, reliable
from testkit import synthetic


@pytest.fixture(scope="module")
def scene():
    z = synthetic.height_field(96)
    return synthetic.gbuffer_from_heights(z), synthetic.gbuffer_from_heights(
        synthetic.blunted(z, sigma_px=2.0))


def _samples(table, scene, lights=synthetic.LIGHTS[:3]):
    truth, scan = scene
    parts = []
    for i, light in enumerate(lights):
        photo = synthetic.photo(table, truth, light)
        parts.append(observations.observe(
            photo, scan.normal, scan.position, np.ones(scan.mask.shape),
            np.zeros(scan.mask.shape, dtype=int), scan.camera_center, light, view_index=i))
    return observations.concatenate(parts)


def _spec(name):
    return next(s for s in database.heldout_specs() if s["name"] == name)


def test_sheen_brightest_pixel_is_not_taken_as_a_specular_peak(scene):
    # cloth is brightest towards grazing, 44 deg from h here: Eq. 2 must not fire
    s = _samples(database.make_table(_spec("heldout_fabric")), scene)
    cand, report = reliable.reliable_candidates(s)
    assert report.skipped.get("brightest") == [0]
    assert len(report.peaks) == 0
    _, literal = reliable.reliable_candidates(
        s, reliable.ReliableSettings(peak_max_angle=np.pi))
    assert len(literal.peaks) == 1  # the paper's literal rule would have moved it


def test_glossy_peak_is_still_corrected(scene):
    s = _samples(database.make_table(_spec("heldout_gold_medium")), scene)
    cand, report = reliable.reliable_candidates(s)
    assert "brightest" not in report.skipped and len(report.peaks) == 1
    k = report.peaks[0]
    h = cand.l[k] + cand.v[k]
    np.testing.assert_allclose(cand.n[k], h / np.linalg.norm(h), atol=1e-12)


def test_monotonicity_is_skipped_where_the_data_reject_it(scene):
    # sheen: reflectance rises towards grazing, i.e. falls as n.h grows (Eq. 1 fails)
    s = _samples(database.make_table(_spec("heldout_random_fabric")), scene)
    strict = reliable.ReliableSettings(monotonicity_max_fraction=1.0, use_curvature=False)
    _, applied = reliable.reliable_candidates(s, strict)
    fraction = applied.removed["monotonicity"] / applied.input
    guarded = reliable.ReliableSettings(monotonicity_max_fraction=min(0.9, fraction - 0.05),
                                        use_curvature=False)
    _, report = reliable.reliable_candidates(s, guarded)
    assert report.skipped.get("monotonicity") == [0]
    assert report.removed["monotonicity"] == 0


def test_guard_is_per_region(scene):
    truth, scan = scene
    tables = [database.make_table(_spec("heldout_random_fabric")),
              database.make_table(_spec("heldout_gold_medium"))]
    region = np.zeros(scan.mask.shape, dtype=int)
    region[:, 48:] = 1
    parts = []
    for i in (0, 1, 2):
        light = synthetic.LIGHTS[i]
        photo = np.where((region == 0)[..., None], synthetic.photo(tables[0], truth, light),
                         synthetic.photo(tables[1], truth, light))
        parts.append(observations.observe(photo, scan.normal, scan.position,
                                          np.ones(scan.mask.shape), region,
                                          scan.camera_center, light, view_index=i))
    s = observations.concatenate(parts)
    strict = reliable.ReliableSettings(monotonicity_max_fraction=1.0, use_curvature=False)
    fraction = []
    for r in (0, 1):
        _, rep = reliable.reliable_candidates(s.subset(np.flatnonzero(s.region == r)), strict)
        fraction.append(rep.removed["monotonicity"] / rep.input)
    assert fraction[0] > fraction[1]  # the sheen breaks Eq. 1 more than the gold
    between = reliable.ReliableSettings(monotonicity_max_fraction=sum(fraction) / 2,
                                        use_curvature=False)
    _, report = reliable.reliable_candidates(s, between)
    assert report.skipped["monotonicity"] == [0]
    assert report.removed["monotonicity"] > 0  # still applied in the gold region
