"""Ridge reconstruction of a full BRDF table from a few samples (Nielsen et al. 2015).

For each colour channel on its own (METHOD.md §2): the observed rho at cells S
are mapped, ``b = x_obs(S) - mean(S)``, ``A = Q[S, :p]``, and the coefficients are
the Tikhonov solution ``c = V diag(s / (s^2 + eta)) U^T b`` of ``A = U diag(s) V^T``;
the table is ``unmap(Q[:, :p] c + mean)``.

Choice of eta (the reference code fixes eta = 40). Ridge is the posterior mean
of a Gaussian model ``b = A c + noise``: with ``Q = U S`` the training channels
have coefficient vectors of unit norm, so the training set itself gives the
prior ``c ~ N(0, tau^2 I)``, ``tau^2 = 1 / n_training_columns``, and then
``eta = sigma^2 / tau^2``. The noise variance sigma^2 (measurement noise plus
the part of the material outside the span) is chosen from the samples by
maximising the marginal likelihood ``b ~ N(0, tau^2 A A^T + sigma^2 I)`` (the
"evidence", MacKay 1992) over a log grid. Nielsen's eta = 40 corresponds to
sigma = 0.3 in log-relative units with 450 training channels.

Choice of p. By default every component of the basis, ``p = k``: ridge is the
posterior mean under the PCA prior, and that prior, not the truncation, keeps the
components the samples cannot pin down near the mean, so nothing forces p <= n.
Nielsen's rule ``p = min(n, k)`` (the matrix whose condition number the sampler
minimised) is ``n_components=n``. Measured on the 5 folds of the measured pack
(``bench/measured_bench.py``'s split, the measured basis with k = 40,
condition-optimal cells, seed 0): the median sphere error at n = 20 falls from
0.144 to 0.138 and at n = 6 from 0.236 to 0.219; on the analytic held-out
materials with the analytic basis it falls at n >= 10 (n = 20: 0.058 to 0.045)
and rises at n = 5 (0.131 to 0.217) (``bench/core_bench.py``). Choosing p from
the samples as well (``select_components=True``: maximum evidence over a grid of
p) is available and measured there too: it truncates too early at small n (e.g.
p = 2 from 5 optimal samples) and loses accuracy. Generalised cross-validation was
measured too and rejected: with n <= p it often interpolates (eta -> 0) and the
table blows up away from the samples.

Samples that fall in one cell are averaged in the mapped space and weighted by
their count (each is an independent observation). Samples in cells outside the
basis (unmeasured in training) are dropped and counted.
"""

from __future__ import annotations

import dataclasses
import functools

import numpy as np

from ..brdf import merl
from ..brdf.basis import Basis
from .sampling import acquisition_condition

SIGMA2_GRID = 10.0 ** np.linspace(-14.0, 2.0, 129)  # noise variance, log-relative units^2
P_GRID = (1, 2, 3, 4, 5, 6, 8, 10, 12, 14, 16, 20, 24, 28, 32, 40, 48, 64, 80, 96, 128)
_ROW_BLOCK = 1 << 17


@dataclasses.dataclass(eq=False)
class Reconstruction:
    """Result of :func:`reconstruct`: the fitted coefficients, and the table from them.

    basis: the basis fitted in. coefficients: (p_max, 3) float64 per channel
    (zero beyond that channel's p); the mapped table is
    ``Q[:, :p_max] coefficients + mean``.
    table: (3, 90, 90, 180) float64 BRDF in 1/sr, finite and >= 0 everywhere,
    expanded on first use (a 1.1 M x k product); :meth:`rho_at` gives the same
    values at chosen cells without it.
    condition: condition number of ``Q[S, :min(n, k)]`` over the used cells S.
    residuals: (n, 3) fitted minus observed rho at the used cells, 1/sr.
    residuals_mapped: (n, 3) the same in the log-relative mapped space.
    cells: (n, 3) int64 the used (unique, in-basis) cells.
    eta: (3,) regulariser per channel (absolute, in the units of s^2).
    n_components: (3,) p per channel.
    noise_sigma: (3,) the noise level sigma per channel (log-relative units) behind
      eta; NaN where eta was given.
    log_evidence: (3,) log marginal likelihood of the chosen model; NaN if eta given.
    n_samples: number of input samples; n_outside: dropped as outside the basis.
    """

    basis: Basis = dataclasses.field(repr=False)
    coefficients: np.ndarray
    condition: float
    residuals: np.ndarray
    residuals_mapped: np.ndarray
    cells: np.ndarray
    eta: np.ndarray
    n_components: np.ndarray
    noise_sigma: np.ndarray
    log_evidence: np.ndarray
    n_samples: int
    n_outside: int

    @functools.cached_property
    def table(self) -> np.ndarray:
        """(3, 90, 90, 180) float64 in 1/sr, every cell (expanded once, then kept)."""
        return self.expand()

    def expand(self) -> np.ndarray:
        """The full table (3, 90, 90, 180) float64 in 1/sr, expanded anew (not kept)."""
        B, coefs = self.basis, self.coefficients
        p = coefs.shape[0]
        mean = B.mean.astype(np.float64)
        x_table = np.empty((len(B.cells), 3))
        # each block of Q is converted to float64 once for all three channels
        for start in range(0, len(B.cells), _ROW_BLOCK):
            sl = slice(start, start + _ROW_BLOCK)
            np.matmul(B.Q[sl, :p].astype(np.float64), coefs, out=x_table[sl])
            x_table[sl] += mean[sl, None]
        return B.table_from_rows(B.from_mapped(x_table))

    def rho_at(self, linear: np.ndarray) -> np.ndarray:
        """rho (N, 3) float64 in 1/sr at flat cell indices (N,): the values of
        :attr:`table` there, from N rows of the basis only."""
        rows = self.basis.source_rows(linear)
        return self.basis.from_mapped(_mapped_at(self.basis, self.coefficients, rows), rows)

    def summary(self) -> dict:
        """JSON-friendly summary for reports."""
        return {
            "condition": float(self.condition),
            "n_samples": int(self.n_samples),
            "n_cells": int(len(self.cells)),
            "n_outside": int(self.n_outside),
            "eta": [float(e) for e in self.eta],
            "n_components": [int(p) for p in self.n_components],
            "noise_sigma": [float(g) for g in self.noise_sigma],
            "log_evidence": [float(g) for g in self.log_evidence],
            "residual_rms_mapped": float(np.sqrt(np.mean(self.residuals_mapped**2))),
        }


def _mapped_at(basis: Basis, coefs: np.ndarray, rows: np.ndarray) -> np.ndarray:
    """The mapped table ``Q[rows, :p] coefs + mean[rows]`` (R, 3) at basis rows (R,)."""
    return (basis.Q[rows, :coefs.shape[0]].astype(np.float64) @ coefs
            + basis.mean[rows].astype(np.float64)[:, None])


def reconstruct(
    basis: Basis,
    cells: np.ndarray,
    values: np.ndarray,
    *,
    eta: float | None = None,
    n_components: int | None = None,
    select_components: bool = False,
    weights: np.ndarray | None = None,
) -> Reconstruction:
    """Reconstruct a full table from rho observed at MERL cells.

    basis: the PCA basis. cells: (M, 3) int bin indices. values: (M, 3) rho in
    1/sr (any float dtype; small negatives from noise are clipped to 0).
    eta: fix the regulariser (absolute) instead of choosing it by evidence.
    n_components: fix p (capped at k) instead of k (``n`` is Nielsen's rule);
    select_components: choose p by evidence instead.
    weights: (M,) relative precision of each sample, finite and >= 0 (default 1
    each): a cell's samples are averaged with these weights and the cell weighs
    their sum; a sample of weight 0 is left out.
    Raises ValueError for NaN/Inf values, mismatched shapes, bad weights, or when
    no sample lies in the basis.
    """
    cells = np.asarray(cells)
    values = np.asarray(values, dtype=np.float64)
    if cells.ndim != 2 or cells.shape[1] != 3:
        raise ValueError(f"cells must have shape (M, 3), got {cells.shape}")
    if values.shape != (len(cells), 3):
        raise ValueError(f"values must have shape ({len(cells)}, 3), got {values.shape}")
    if not np.all(np.isfinite(values)):
        bad = int(np.sum(~np.isfinite(values).all(axis=1)))
        raise ValueError(f"values hold NaN or Inf in {bad} of {len(values)} samples")
    if len(cells) == 0:
        raise ValueError("no samples to reconstruct from")
    if weights is not None:
        weights = np.asarray(weights, dtype=np.float64)
        if weights.shape != (len(cells),):
            raise ValueError(f"weights must have shape ({len(cells)},), got {weights.shape}")
        if not np.all(np.isfinite(weights)) or np.any(weights < 0):
            raise ValueError("weights must be finite and >= 0")
        if not np.any(weights > 0):
            raise ValueError("every sample has weight 0")

    rows = basis.rows_of(merl.linear_index(cells))
    inside = rows >= 0
    n_outside = int(np.sum(~inside))
    if not inside.any():
        raise ValueError(
            f"none of the {len(cells)} samples lies in a cell the basis covers"
        )
    if weights is not None:
        inside &= weights > 0
        if not inside.any():
            raise ValueError("every sample in a cell the basis covers has weight 0")
    rows, values = rows[inside], values[inside]
    x = basis.to_mapped(values, rows)  # (M, 3)

    # Duplicate cells: (weighted) mean in the mapped space, weight = count (sum).
    urows, inverse, counts = np.unique(rows, return_inverse=True, return_counts=True)
    xu = np.zeros((len(urows), 3))
    if weights is None:
        np.add.at(xu, inverse, x)
        total = counts.astype(np.float64)
    else:
        w_in = weights[inside]
        np.add.at(xu, inverse, w_in[:, None] * x)
        total = np.bincount(inverse, weights=w_in, minlength=len(urows))
    xu /= total[:, None]
    w = np.sqrt(total)[:, None]
    bw = w * (xu - basis.mean[urows].astype(np.float64)[:, None])
    A_full = w * basis.Q[urows].astype(np.float64)

    k = basis.n_components
    if n_components is not None:
        p_grid = [int(np.clip(n_components, 1, k))]
    elif select_components:
        p_grid = sorted({p for p in P_GRID if p <= k} | {k})
    else:
        p_grid = [k]
    tau2 = 1.0 / basis.info["n_columns"]
    best: list = [None, None, None]
    for p in p_grid:
        U, s, Vt = np.linalg.svd(A_full[:, :p], full_matrices=False)
        beta = U.T @ bw  # (r, 3)
        if eta is None:
            log_ev, sigma2 = _evidence(s, beta, bw, tau2)
        else:
            log_ev = np.full(3, np.nan)
            sigma2 = np.full(3, eta * tau2)
        for c in range(3):
            if best[c] is None or log_ev[c] > best[c][0]:
                e = sigma2[c] / tau2
                coef = Vt.T @ ((s / (s**2 + e)) * beta[:, c])
                best[c] = (log_ev[c], p, e, sigma2[c], coef)

    p_max = max(best[c][1] for c in range(3))
    coefs = np.zeros((p_max, 3))
    for c in range(3):
        coefs[:best[c][1], c] = best[c][4]
    fitted = _mapped_at(basis, coefs, urows)
    return Reconstruction(
        basis=basis,
        coefficients=coefs,
        condition=acquisition_condition(basis.Q, urows),
        residuals=basis.from_mapped(fitted, urows) - basis.from_mapped(xu, urows),
        residuals_mapped=fitted - xu,
        cells=merl.cells_from_linear(basis.cells[urows]),
        eta=np.array([best[c][2] for c in range(3)]),
        n_components=np.array([best[c][1] for c in range(3)]),
        noise_sigma=np.array([np.sqrt(best[c][3]) if eta is None else np.nan
                              for c in range(3)]),
        log_evidence=np.array([best[c][0] for c in range(3)]),
        n_samples=int(len(cells)),
        n_outside=n_outside,
    )


HUBER_K = 1.345  # Huber's threshold, robust standard deviations (95 % efficiency)


def robust_reconstruct(
    basis: Basis,
    cells: np.ndarray,
    values: np.ndarray,
    *,
    weights: np.ndarray | None = None,
    iterations: int = 10,
    **options,
) -> Reconstruction:
    """:func:`reconstruct` with a Huber loss in the mapped (log-relative) space, by
    iteratively reweighted least squares: meant for many samples (all of a
    region's reliable ones), a few of which are wrong (a texture edge, an
    interreflection, a normal far off).

    Each round refits with weights ``w_i = min(1, HUBER_K / z_i)``, where ``z_i``
    is sample i's largest mapped residual over the channels in units of that
    channel's robust standard deviation (1.4826 x the median absolute residual),
    times the caller's ``weights``. Stops when no weight moves by more than 1e-3,
    after ``iterations`` rounds (>= 1) at most. cells, values, weights and
    ``options`` (eta, n_components, select_components) as for :func:`reconstruct`,
    which checks them. Deterministic.
    """
    if iterations < 1:
        raise ValueError(f"iterations must be at least 1, got {iterations}")
    rec = reconstruct(basis, cells, values, weights=weights, **options)
    rows = basis.rows_of(merl.linear_index(np.asarray(cells)))
    inside = rows >= 0
    x = basis.to_mapped(np.asarray(values, dtype=np.float64)[inside], rows[inside])
    prior = np.ones(len(rows)) if weights is None else np.asarray(weights, np.float64)
    w = prior.copy()
    tiny = np.finfo(np.float64).tiny
    for _ in range(iterations - 1):
        r = x - _mapped_at(basis, rec.coefficients, rows[inside])  # (M, 3)
        scale = np.maximum(1.4826 * np.median(np.abs(r), axis=0), 1e-12)
        z = np.max(np.abs(r) / scale, axis=1)
        new = prior.copy()
        new[inside] *= np.minimum(1.0, HUBER_K / np.maximum(z, tiny))
        moved = float(np.max(np.abs(new - w)))
        w = new
        rec = reconstruct(basis, cells, values, weights=w, **options)
        if moved <= 1e-3:
            break
    return rec


def _evidence(s: np.ndarray, beta: np.ndarray, b: np.ndarray, tau2: float):
    """Log marginal likelihood of ``b ~ N(0, tau2 A A^T + sigma2 I)`` maximised over
    SIGMA2_GRID, per channel. s: (r,) singular values of A (n x p), beta = U^T b (r, 3),
    b: (n, 3). Returns (log_evidence (3,), sigma2 (3,))."""
    n, r = b.shape[0], len(s)
    perp = np.maximum(np.sum(b**2, axis=0) - np.sum(beta**2, axis=0), 0.0)  # (3,)
    sig2 = SIGMA2_GRID[:, None]  # (G, 1)
    var = tau2 * s[None, :] ** 2 + sig2  # (G, r)
    ll = -0.5 * (
        np.log(var).sum(axis=1)[:, None]
        + np.einsum("gr,rc->gc", 1.0 / var, beta**2)
        + (n - r) * np.log(sig2)
        + perp[None, :] / sig2
        + n * np.log(2.0 * np.pi)
    )  # (G, 3)
    i = np.argmax(ll, axis=0)
    return ll[i, np.arange(3)], SIGMA2_GRID[i]
