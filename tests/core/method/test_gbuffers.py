"""core.method.gbuffers.footprint_normals: a fine G-buffer grouped by photo pixel."""

import numpy as np
import pytest

from brdf_reconstruct.core.method import gbuffers


def _fine(rows, cols, mask=None):
    """G-buffers whose normal at fine pixel (r, c) encodes (r, c): (r, c, 1) unnormalised
    (the grouping is checked, not the unit length)."""
    r, c = np.mgrid[0:rows, 0:cols].astype(np.float64)
    normal = np.stack([r, c, np.ones_like(r)], axis=-1)
    mask = np.ones((rows, cols), dtype=bool) if mask is None else mask
    return gbuffers.GBuffers(
        normal=np.where(mask[..., None], normal, 0.0), position=np.zeros((rows, cols, 3)),
        visibility=np.zeros((rows, cols)), region=np.where(mask, 0, -1).astype(np.int32),
        mask=mask, camera_center=np.zeros(3))


@pytest.mark.parametrize("factor", [1, 2, 3])
def test_each_photo_pixel_gets_the_fine_pixels_it_covers_row_major(factor):
    rows, cols = 4 * factor, 5 * factor
    fp = gbuffers.footprint_normals(_fine(rows, cols), factor)
    assert fp.shape == (4, 5, factor * factor, 3) and fp.dtype == np.float64
    for i, j, a, b in [(0, 0, 0, 0), (3, 4, factor - 1, factor - 1), (2, 1, 0, factor - 1),
                       (1, 3, factor - 1, 0)]:
        assert fp[i, j, a * factor + b, :2].tolist() == [i * factor + a, j * factor + b]


def test_fine_pixels_off_the_object_are_nan_and_the_rest_kept():
    mask = np.ones((4, 6), dtype=bool)
    mask[0, 1] = mask[3, 5] = False  # photo pixels (0, 0) point 1 and (1, 2) point 3
    fp = gbuffers.footprint_normals(_fine(4, 6, mask), 2)
    off = ~np.isfinite(fp).all(axis=-1)
    assert off.sum() == 2 and off[0, 0, 1] and off[1, 2, 3]
    assert np.isnan(fp[0, 0, 1]).all()


@pytest.mark.parametrize("factor, shape, words", [
    (0, (4, 4), "positive integer"), (1.5, (4, 4), "positive integer"),
    (2, (5, 4), "not 2 x a photo's size"), (3, (6, 4), "not 3 x a photo's size")])
def test_a_wrong_factor_or_fine_size_is_one_sentence(factor, shape, words):
    with pytest.raises(ValueError, match=words):
        gbuffers.footprint_normals(_fine(*shape), factor)
