"""Fixtures of the method tests (no bpy)."""

import pytest

from testkit import synthetic


@pytest.fixture(scope="module")
def scene():
    """The synthetic height field (96 x 96 pixels) as G-buffers: (truth, scan), the
    scan's heights blunted by a 2-pixel Gaussian as a photogrammetry mesh is."""
    z = synthetic.height_field(96)
    truth = synthetic.gbuffer_from_heights(z)
    scan = synthetic.gbuffer_from_heights(synthetic.blunted(z, sigma_px=2.0))
    return truth, scan
