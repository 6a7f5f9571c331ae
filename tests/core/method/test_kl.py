"""KL divergence of log-binned intensity histograms (paper Sec. 3.2, METHOD.md §6)."""

import math

import numpy as np
import pytest

from brdf_reconstruct.core.method import kl
from brdf_reconstruct.core.method.kl import kl_divergence


@pytest.fixture
def hdr_rgb():
    """(5000, 3) HDR linear radiance: log-normal, about four decades."""
    rng = np.random.default_rng(7)
    return np.exp(rng.normal(0.0, 1.2, size=(5000, 3)))


def test_identical_sets_give_zero(hdr_rgb):
    assert kl_divergence(hdr_rgb, hdr_rgb) == 0.0
    assert kl_divergence(hdr_rgb, hdr_rgb, mode="per_channel") == 0.0
    assert kl_divergence(hdr_rgb[:, 0], hdr_rgb[:, 0].copy()) == 0.0


def test_non_negative_on_random_pairs():
    rng = np.random.default_rng(1)
    for _ in range(20):
        a = np.exp(rng.normal(0.0, 1.0, size=(rng.integers(1, 400), 3)))
        b = np.exp(rng.normal(rng.normal(), 1.0, size=(rng.integers(1, 400), 3)))
        for mode in kl.MODES:
            value = kl_divergence(a, b, n_bins=int(rng.integers(1, 80)), mode=mode)
            assert value >= 0.0 and math.isfinite(value)


def test_finite_for_disjoint_supports():
    photo = np.full(100, 1.0)
    rendered = np.full(100, 1000.0)
    value = kl_divergence(photo, rendered)
    assert math.isfinite(value) and value > 0.0
    # All photo mass sits where the render has only the floor: about ln(1/floor).
    assert value == pytest.approx(math.log(1.0 / 1e-6), rel=0.05)


def test_smaller_floor_gives_larger_kl_for_disjoint_supports():
    photo = np.full(100, 1.0)
    rendered = np.full(100, 1000.0)
    values = [kl_divergence(photo, rendered, floor=f) for f in (1e-2, 1e-4, 1e-6, 1e-9)]
    assert all(b > a for a, b in zip(values, values[1:], strict=False))


@pytest.mark.parametrize(
    "scales", [(1.0, 1.5, 3.0, 10.0, 30.0), (1.0, 1 / 1.5, 1 / 3, 0.1, 1 / 30)]
)
def test_grows_as_render_is_scaled_away(hdr_rgb, scales):
    values = [kl_divergence(hdr_rgb, s * hdr_rgb) for s in scales]
    assert values[0] == 0.0
    assert all(b > a for a, b in zip(values, values[1:], strict=False)), values


def test_invariant_to_pixel_order(hdr_rgb):
    rng = np.random.default_rng(3)
    rendered = 2.0 * hdr_rgb[:3000]
    for mode in kl.MODES:
        base = kl_divergence(hdr_rgb, rendered, mode=mode)
        shuffled = kl_divergence(rng.permutation(hdr_rgb), rng.permutation(rendered), mode=mode)
        assert shuffled == base


def test_float32_input(hdr_rgb):
    a32 = hdr_rgb.astype(np.float32)
    b32 = (1.7 * hdr_rgb).astype(np.float32)
    assert kl_divergence(a32, a32) == 0.0
    expected = kl_divergence(a32.astype(np.float64), b32.astype(np.float64))
    assert kl_divergence(a32, b32) == expected
    assert expected > 0.0


def test_luminance_mode_is_kl_of_rec709_luminance(hdr_rgb):
    rendered = hdr_rgb[:, ::-1] * 1.3
    y = hdr_rgb @ np.array([0.2126, 0.7152, 0.0722])
    y_r = rendered @ np.array([0.2126, 0.7152, 0.0722])
    assert kl_divergence(hdr_rgb, rendered) == kl_divergence(y, y_r)


def test_per_channel_mode_is_sum_of_channel_kls(hdr_rgb):
    rendered = hdr_rgb * np.array([1.0, 2.0, 0.25])
    expected = sum(kl_divergence(hdr_rgb[:, c], rendered[:, c]) for c in range(3))
    assert kl_divergence(hdr_rgb, rendered, mode="per_channel") == pytest.approx(expected)


def test_per_channel_sees_a_hue_shift_luminance_misses():
    # Swap the colour between two groups of pixels: every pixel's luminance set is
    # unchanged, but each channel's distribution changes.
    red = np.array([1.0, 0.1, 0.1])
    blue = np.array([0.1, 0.1, 1.0])
    y_red, y_blue = red @ kl.LUMINANCE_WEIGHTS, blue @ kl.LUMINANCE_WEIGHTS
    photo = np.vstack([np.tile(red, (100, 1)), np.tile(blue, (100, 1))])
    # Same luminance histogram: scale the swapped colours to keep each luminance.
    rendered = np.vstack(
        [np.tile(blue * y_red / y_blue, (100, 1)), np.tile(red * y_blue / y_red, (100, 1))]
    )
    assert kl_divergence(photo, rendered) == pytest.approx(0.0, abs=1e-12)
    assert kl_divergence(photo, rendered, mode="per_channel") > 1.0


def test_non_positive_and_below_range_values_go_to_first_bin():
    # -1, 0 and 0.01 (below the given lower edge) all land in the first bin.
    photo = np.array([-1.0, 0.0, 0.01])
    rendered = np.array([0.5, 0.5, 0.5])  # with 2 bins on (0.1, 100) the first is (0.1, 3.16)
    two = {"n_bins": 2, "range": (0.1, 100.0)}
    assert kl_divergence(photo, rendered, **two) == pytest.approx(0.0, abs=1e-12)
    assert kl_divergence(photo, [5.0], **two) > 1.0
    # Above the upper edge -> last bin.
    assert kl_divergence([500.0, 900.0], [90.0], range=(0.1, 100.0)) == pytest.approx(
        0.0, abs=1e-12
    )


def test_all_zero_input_gives_zero():
    assert kl_divergence(np.zeros((10, 3)), np.zeros((4, 3))) == 0.0


def test_single_pixel_each():
    assert kl_divergence([2.0], [2.0]) == 0.0
    assert kl_divergence([2.0], [3.0]) > 0.0


def test_bin_edges_are_log_spaced_on_joint_positive_range():
    edges = kl.log_bin_edges(np.array([0.0, 0.01, 1.0]), np.array([-3.0, 100.0]), n_bins=4)
    np.testing.assert_allclose(edges, [0.01, 0.1, 1.0, 10.0, 100.0])


@pytest.mark.parametrize(
    "photo, rendered, kwargs, message",
    [
        (np.zeros((0, 3)), np.ones((5, 3)), {}, "photo is empty"),
        (np.ones(5), np.zeros(0), {}, "rendered is empty"),
        (np.array([1.0, np.nan]), np.ones(2), {}, "NaN or Inf"),
        (np.ones((2, 3)), np.array([[1.0, np.inf, 1.0]]), {}, "NaN or Inf"),
        (np.ones((2, 4)), np.ones((2, 4)), {}, r"\(N, 3\) or \(N,\)"),
        (np.ones((2, 3)), np.ones(2), {}, "both"),
        (np.ones(3), np.ones(3), {"n_bins": 0}, "n_bins"),
        (np.ones(3), np.ones(3), {"floor": 0.0}, "floor"),
        (np.ones(3), np.ones(3), {"mode": "rgb"}, "mode"),
        (np.ones(3), np.ones(3), {"range": (0.0, 1.0)}, "range"),
        (np.ones(3), np.ones(3), {"range": (2.0, 1.0)}, "range"),
    ],
)
def test_bad_input_raises_clear_value_error(photo, rendered, kwargs, message):
    with pytest.raises(ValueError, match=message):
        kl_divergence(photo, rendered, **kwargs)
