"""What the observation and reliable-region tests share (test_observations.py,
test_reliable.py, test_pipeline.py): a Lambertian table and
``observations.observe`` with the tests' defaults. Their scene, the synthetic
height field and its blunted scan, is the ``scene`` fixture of conftest.py."""

import numpy as np

from brdf_reconstruct.core.brdf import merl
from brdf_reconstruct.core.method import observations


def lambert_table(albedo=0.5):
    """A Lambertian table (3, 90, 90, 180): albedo / pi in every valid cell, NaN elsewhere."""
    table = np.full((3, merl.N_CELLS), np.nan)
    table[:, merl.valid_cells()] = albedo / np.pi
    return table.reshape(3, *merl.SHAPE)


def observe(photo, g, light, settings=None, **kw):
    """``observations.observe`` of ``photo`` on the G-buffers ``g`` (a
    ``synthetic.GBuffer``): everything visible and one region (0) unless
    ``visibility`` or ``region`` is given; other keywords pass through."""
    kw.setdefault("visibility", np.ones(g.mask.shape))
    kw.setdefault("region", np.zeros(g.mask.shape, dtype=int))
    return observations.observe(photo, g.normal, g.position, kw.pop("visibility"),
                                kw.pop("region"), g.camera_center, light,
                                settings=settings, **kw)
