"""KL divergence between the intensity distributions of two sets of pixels.

The paper (Sec. 3.2, METHOD.md §6) renders each candidate reconstruction from
the photo viewpoints and keeps the one whose intensity distribution is closest,
in Kullback-Leibler divergence, to the photos'. This module computes that
number from two sets of linear radiance values.

Choices, all fixed here so every caller compares like with like:

- Histograms on log-spaced bins: radiance is high dynamic range (a specular
  highlight can be 10^3 times the diffuse level), and equal-width linear bins
  would put almost every pixel in the first bin.
- By default the bin edges span the joint positive range of both sets,
  ``[min positive value, max value]``, in log space. Values ``<= 0`` (black
  background, shadow, noise below zero) and values below the lower edge fall
  in the first bin; values above the upper edge (only possible with an
  explicit ``range``) fall in the last bin.
- A floor: ``floor`` is added to every bin's probability, and the histogram is
  renormalised, so an empty bin never makes the divergence infinite. A smaller
  floor punishes mass where the other histogram has none more heavily.
- Natural logarithm: the result is in nats.
"""

from __future__ import annotations

import numpy as np

# Rec. 709 / sRGB primaries, linear RGB -> relative luminance Y.
LUMINANCE_WEIGHTS = np.array([0.2126, 0.7152, 0.0722])
MODES = ("luminance", "per_channel")


def kl_divergence(
    photo,
    rendered,
    n_bins: int = 64,
    floor: float = 1e-6,
    mode: str = "luminance",
    range=None,  # noqa: A002 - numpy.histogram's name for the same argument
) -> float:
    """KL(P_photo || P_rendered) of the intensity histograms of two pixel sets.

    Parameters
    ----------
    photo, rendered : array_like, (N, 3) or (N,)
        Linear radiance (W/(m^2 sr), or any linear unit common to both), RGB
        rows or single intensities; any float dtype. The two sets may hold
        different numbers of pixels (histograms are normalised) but must have
        the same layout. Pixel order does not matter.
    n_bins : int
        Number of log-spaced bins, >= 1.
    floor : float
        Probability added to every bin before renormalising, > 0. Keeps the
        divergence finite when the supports are disjoint; the maximum possible
        value is about ``ln(1 / floor)``.
    mode : {"luminance", "per_channel"}
        For RGB input: "luminance" (default) histograms the Rec. 709 luminance
        ``0.2126 R + 0.7152 G + 0.0722 B``, the paper's single "intensity"
        distribution; "per_channel" returns the sum of the three channel KLs,
        each on its own joint range, which also sees a colour shift that keeps
        luminance. Ignored for (N,) input, which is already an intensity.
    range : (float, float) or None
        ``(lo, hi)``, ``0 < lo < hi``, the bin edges' span in the same unit as
        the values. None: the joint positive range of both sets (per channel in
        "per_channel" mode). If neither set holds a positive value, every value
        falls in the first bin and the divergence is 0.

    Returns
    -------
    float
        KL divergence in nats, finite and >= 0; exactly 0 when both sets have
        the same histogram.

    Raises
    ------
    ValueError
        Empty input, NaN or Inf values, a wrong shape, or a bad parameter.
    """
    p = _as_pixels(photo, "photo")
    q = _as_pixels(rendered, "rendered")
    if p.ndim != q.ndim:
        raise ValueError(
            f"photo and rendered must both be (N, 3) or both (N,), got shapes "
            f"{p.shape} and {q.shape}"
        )
    if isinstance(n_bins, bool) or not isinstance(n_bins, int | np.integer) or n_bins < 1:
        raise ValueError(f"n_bins must be an integer >= 1, got {n_bins!r}")
    floor = float(floor)
    if not (np.isfinite(floor) and floor > 0.0):
        raise ValueError(f"floor must be a finite number > 0, got {floor!r}")
    if mode not in MODES:
        raise ValueError(f"mode must be one of {MODES}, got {mode!r}")
    if range is not None:
        lo, hi = (float(x) for x in range)
        if not (np.isfinite(lo) and np.isfinite(hi) and 0.0 < lo < hi):
            raise ValueError(f"range must be (lo, hi) with 0 < lo < hi, finite; got {range!r}")
        range = (lo, hi)

    if p.ndim == 1:
        return _kl_1d(p, q, n_bins, floor, range)
    if mode == "luminance":
        return _kl_1d(p @ LUMINANCE_WEIGHTS, q @ LUMINANCE_WEIGHTS, n_bins, floor, range)
    return float(sum(_kl_1d(p[:, c], q[:, c], n_bins, floor, range) for c in (0, 1, 2)))


def log_bin_edges(photo, rendered, n_bins: int = 64, range=None):  # noqa: A002
    """Bin edges (n_bins + 1,) float64, log-spaced, used by :func:`kl_divergence`.

    photo, rendered: (N,) intensities (already validated, float64). With
    ``range=None`` the edges span the joint positive range; when that range
    is a single value it is widened by a factor e^(1/2) each way, and when no
    value is positive the span is the arbitrary ``(1, e)``.
    """
    if range is not None:
        lo, hi = range
    else:
        both = np.concatenate([photo, rendered])
        positive = both[both > 0.0]
        if positive.size == 0:
            lo, hi = 1.0, np.e
        else:
            lo, hi = float(positive.min()), float(positive.max())
            if not hi > lo:
                lo, hi = lo * np.exp(-0.5), hi * np.exp(0.5)
    return np.exp(np.linspace(np.log(lo), np.log(hi), n_bins + 1))


def _as_pixels(x, name: str) -> np.ndarray:
    a = np.asarray(x, dtype=np.float64)
    if not (a.ndim == 1 or (a.ndim == 2 and a.shape[1] == 3)):
        raise ValueError(f"{name} must have shape (N, 3) or (N,), got {a.shape}")
    if a.shape[0] == 0:
        raise ValueError(f"{name} is empty: no pixel values to compare")
    if not np.all(np.isfinite(a)):
        raise ValueError(f"{name} holds NaN or Inf values; drop those pixels first")
    return a


def _histogram(values: np.ndarray, edges: np.ndarray, floor: float) -> np.ndarray:
    """Floored, normalised probabilities (n_bins,) of ``values`` on log ``edges``."""
    n_bins = len(edges) - 1
    log_lo, log_hi = np.log(edges[0]), np.log(edges[-1])
    index = np.zeros(values.shape, dtype=np.int64)  # <= 0 -> first bin
    positive = values > 0.0
    t = (np.log(values[positive]) - log_lo) / (log_hi - log_lo) * n_bins
    index[positive] = np.clip(np.floor(t), 0, n_bins - 1)  # outside the span -> end bins
    prob = np.bincount(index, minlength=n_bins) / values.size + floor
    return prob / prob.sum()


def _kl_1d(p: np.ndarray, q: np.ndarray, n_bins: int, floor: float, range) -> float:  # noqa: A002
    edges = log_bin_edges(p, q, n_bins, range)
    hp = _histogram(p, edges, floor)
    hq = _histogram(q, edges, floor)
    # Rounding can leave -1e-17 when the histograms (nearly) agree; KL >= 0.
    return max(float(np.sum(hp * np.log(hp / hq))), 0.0)
