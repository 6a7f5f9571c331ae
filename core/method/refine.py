"""Photo-consistency refinement: the chosen reconstruction refitted to every pixel.

A trial reconstructs from a few samples in the basis' log mapping, where a
highlight 10^3 above the diffuse level weighs no more than a dark pixel; the
table that comes out can miss the photos' energy by a factor of ten (issue 15).
This step refits the chosen trial's basis coefficients ``c`` (per colour channel)
to the photos themselves, minimising

    sum_i (L_i(c) - L_i)^2 / s_L^2  +  sum_j (x_j(c) - x_j)^2 / s_x^2  +  |c|^2 / tau^2

- ``L_i(c) = rho(c; cell_i) E_i (n_i . l_i)``: the radiance the table predicts at
  every observed pixel i (``samples``: the region's samples after the up-front
  removals, highlights included), against the photo's linear value ``L_i``;
- ``x_j(c) = Q_j c + mean_j``: the log-mapped table at the trusted samples j
  (``trusted``: the reliable region's), against their mapped rho ``x_j``; this
  term keeps the dim part of the lobe, which the radiance term cannot see (a
  mirror's tail at 10^-4 of its peak) and the KL's log histograms do;
- ``|c|^2 / tau^2``: the basis' prior, as in ``core.method.reconstruct``.

The fit runs in two stages per channel, both Levenberg-Marquardt on the
Gauss-Newton normal equations (k x k) from the chosen trial's coefficients:
first the radiance term alone (with the prior), then both terms. Started with
both, a trial that misses the highlight is held there: the radiance term's noise
level, estimated from its own large residuals, makes it weigh too little for the
step to find the peak (the black phenolic, exact normals: sphere error 0.87
joint from the start, 0.18 radiance first). The noise levels are re-estimated
at every iteration as the mean squared residual of their term (each term weighs
as its own likelihood). The mapped term is robust: Huber weights (1.345 robust
standard deviations, from the residuals' median absolute deviation), so a few
trusted samples that are wrong (a texture edge, an interreflection) do not pull
the lobe; the radiance term is not, since its largest residuals are the
highlights this step exists for.

Measured (``bench/photo_bench.py``, docs/results.md): with exact normals it
brings the sphere error of mirror-like materials from about 0.9 to below 0.1; on
a blunted scan the photos' highlights sit where the scan's normals do not put
them, and the refit alone cannot place them. With per-pixel normal noise it is
unsafe: normals jittered by 1 degree (the numpy test scene,
``tests/core/method/test_refine.py``) took a mirror's peak to 1900x the true one
(the basis extrapolates up to e^5 beyond its training range at cells no pixel
sees; sphere error 90 against 0.36 without the refit) and a glossy plastic's to
6x (0.95 against 0.26), where the trials keep both within a factor 2. So the
pipeline leaves it off by default.
"""

from __future__ import annotations

import numpy as np

from ..brdf import merl
from ..brdf.basis import EPS, Basis, _mapping_f64
from .observations import Samples
from .reconstruct import HUBER_K, Reconstruction

_MARGIN = 5.0  # as Basis.from_mapped: extrapolation up to e^5 beyond the training range


def photo_consistent(
    basis: Basis,
    start: Reconstruction,
    samples: Samples,
    trusted: Samples,
    iterations: int = 20,
    normal_sigma: float = 0.0,
    normal_draws: int = 8,
) -> Reconstruction:
    """Refit ``start``'s coefficients to the photos (module docstring).

    basis: the basis ``start`` was fitted in. samples: the region's observed
    samples (radiance, irradiance, n, l, v, cells used; N >= 1). trusted: the
    reliable samples (rho and cells used) for the mapped term. iterations:
    Gauss-Newton steps per channel, >= 1. normal_sigma: the scan normals' error,
    radians (standard deviation per tangent axis, >= 0); when positive, the
    radiance term predicts each pixel as the mean over ``normal_draws`` normals
    drawn about the scan's (a fixed seed), so a lobe blurred by wrong normals is
    not fitted as a wider lobe (an experiment, off by default:
    ``bench/refit_bench.py``, docs/results.md). Returns a new Reconstruction with
    all k coefficients per channel; its residuals are at the trusted samples'
    cells. Deterministic: no random choice beyond the seeded draws.
    """
    if iterations < 1:
        raise ValueError(f"iterations must be at least 1, got {iterations}")
    if not (np.isfinite(normal_sigma) and normal_sigma >= 0.0):
        raise ValueError(f"normal_sigma must be a finite angle >= 0 radians, got {normal_sigma}")
    if normal_draws < 1:
        raise ValueError(f"normal_draws must be at least 1, got {normal_draws}")
    if len(samples) == 0:
        raise ValueError("no observed samples to refine against")
    k = basis.n_components
    coefs = np.zeros((k, 3))
    coefs[:start.coefficients.shape[0]] = start.coefficients
    weight, m_eps = _mapping_f64(basis)
    lo, hi = basis.x_range

    # the radiance term's lookups, one set per normal draw: (Q (N, k), mean, weight
    # and m_eps (N,), shading (N, 3)); one draw, the scan's normals, by default
    # (each draw holds its own Q: N x k float64, 8 draws 8x the memory of one)
    if normal_sigma == 0.0:
        draws = [_lookups(basis, weight, m_eps, samples.cells, samples.n, samples)]
    else:
        rng = np.random.default_rng(0)
        n = np.asarray(samples.n, dtype=np.float64)
        draws = []
        for _ in range(normal_draws):
            t = rng.normal(0.0, normal_sigma, n.shape)
            t -= np.einsum("ij,ij->i", t, n)[:, None] * n  # tangent offsets
            m = n + t
            m /= np.linalg.norm(m, axis=1, keepdims=True)
            draws.append(_lookups(basis, weight, m_eps,
                                  merl.cells_about_normals(m, samples.l, samples.v), m,
                                  samples))
    radiance = np.asarray(samples.radiance, dtype=np.float64)

    trows = basis.rows_of(merl.linear_index(trusted.cells))
    inside = trows >= 0
    trows = trows[inside]
    Qt = basis.Q[trows].astype(np.float64)  # (M, k)
    mean_t = basis.mean[trows].astype(np.float64)
    x_t = basis.to_mapped(np.asarray(trusted.rho, dtype=np.float64)[inside], trows)

    tau2 = 1.0 / basis.info["n_columns"]
    tiny = np.finfo(np.float64).tiny

    def predict(c, ch, jacobian=True):
        """Radiance (N,) of channel ``ch`` and its Jacobian (N, k) in c (None if not
        asked for): the mean over the normal draws."""
        value, jac = 0.0, 0.0
        for Q, mean, weight, m_eps, shading in draws:
            g = shading[:, ch]
            e = m_eps * np.exp(np.clip(Q @ c + mean, lo - _MARGIN, hi + _MARGIN))
            value = value + np.maximum(e - EPS, 0.0) / weight * g
            if jacobian:
                jac = jac + (e / weight * g)[:, None] * Q
        return value / len(draws), (jac / len(draws) if jacobian else None)

    def huber(r):
        """IRLS weights (n,) of residuals r (n,) under a Huber loss (1 in the core)."""
        if len(r) == 0:
            return np.ones(0)
        scale = 1.4826 * float(np.median(np.abs(r - np.median(r))))
        scale = max(scale, 1e-12 * float(np.sqrt(np.mean(r**2))), tiny)
        return np.minimum(1.0, HUBER_K * scale / np.maximum(np.abs(r), tiny))

    def profiled(c, ch, obs, xt):
        """-2 log posterior of c with both noise levels at their maximum (the
        terms' mean squared residuals), up to a constant: comparable between fits."""
        r_l, r_x = predict(c, ch, False)[0] - obs, Qt @ c + mean_t - xt
        w_x = huber(r_x)
        value = len(r_l) * np.log(max(float(np.mean(r_l**2)), tiny)) + c @ c / tau2
        if len(r_x):
            value += np.sum(w_x) * np.log(max(float(np.sum(w_x * r_x**2) / np.sum(w_x)), 1e-8))
        return float(value)

    def fit_channel(c, ch, obs, xt, use_log):
        for _ in range(iterations):
            pred, J = predict(c, ch)
            r_l = pred - obs
            s2_l = max(float(np.mean(r_l**2)), 1e-12 * float(np.mean(obs**2)), tiny)
            H, grad = J.T @ J / s2_l, J.T @ r_l / s2_l
            w_x = s2_x = None
            if use_log:  # the mapped term; not computed in the first stage
                r_x = Qt @ c + mean_t - xt
                w_x = huber(r_x)
                s2_x = max(float(np.sum(w_x * r_x**2) / max(np.sum(w_x), tiny))
                           if len(r_x) else 1.0, 1e-8)
                H = H + (Qt.T * w_x) @ Qt / s2_x
                grad = grad + Qt.T @ (w_x * r_x) / s2_x
            H, grad = H + np.eye(k) / tau2, grad + c / tau2

            def objective(cn, pn, s2_l=s2_l, s2_x=s2_x, w_x=w_x, obs=obs, xt=xt):
                value = np.sum((pn - obs) ** 2) / s2_l
                if w_x is not None:
                    value = value + np.sum(w_x * (Qt @ cn + mean_t - xt) ** 2) / s2_x
                return value + cn @ cn / tau2

            f0, damping, moved = objective(c, pred), 1e-4, False
            for _ in range(12):
                step = np.linalg.solve(H + damping * np.diag(np.diag(H)), -grad)
                trial = c + step
                value = objective(trial, predict(trial, ch, False)[0])
                if np.isfinite(value) and value < f0:
                    c, moved = trial, True
                    break
                damping *= 5.0
            if not moved or f0 - value <= 1e-9 * f0:  # no step, or settled
                break
        return c

    for ch in range(3):
        obs, xt = radiance[:, ch], x_t[:, ch]
        c = coefs[:, ch].copy()
        # two paths, both terms at the end: from the trial, and through the
        # radiance term alone; the more probable end point is kept
        paths = [fit_channel(c, ch, obs, xt, use_log=True),
                 fit_channel(fit_channel(c, ch, obs, xt, use_log=False), ch, obs, xt,
                             use_log=True)]
        coefs[:, ch] = min(paths, key=lambda cp: profiled(cp, ch, obs, xt))

    fitted = Qt @ coefs + mean_t[:, None]
    return Reconstruction(
        basis=basis, coefficients=coefs, condition=start.condition,
        residuals=basis.from_mapped(fitted, trows) - basis.from_mapped(x_t, trows),
        residuals_mapped=fitted - x_t,
        cells=np.asarray(trusted.cells)[inside],
        eta=np.asarray(start.eta, dtype=np.float64), n_components=np.full(3, k),
        noise_sigma=np.full(3, np.nan), log_evidence=np.full(3, np.nan),
        n_samples=int(len(samples)), n_outside=int(np.sum(~inside)))


def _lookups(basis: Basis, weight, m_eps, cells, n, samples: Samples):
    """The radiance term's per-sample basis rows for cells (N, 3) about normals n
    (N, 3): Q (N, k) and mean (N,) float64, the mapping's weight and m_eps (N,),
    and the shading E (n . l)+ (N, 3)."""
    rows = basis.source_rows(merl.linear_index(cells))
    cos_l = np.maximum(np.einsum("ij,ij->i", n, samples.l), 0.0)
    return (basis.Q[rows].astype(np.float64), basis.mean[rows].astype(np.float64),
            weight[rows], m_eps[rows],
            np.asarray(samples.irradiance, dtype=np.float64) * cos_l[:, None])


def relative_rmse(rec: Reconstruction, samples: Samples) -> float:
    """Relative RMSE of the radiance ``rec`` predicts at ``samples`` (N,) against
    their photos' values: sqrt(sum (L(c) - L)^2 / sum L^2), dimensionless; NaN if
    every value is 0."""
    rho = rec.rho_at(merl.linear_index(samples.cells))
    cos_l = np.maximum(np.einsum("ij,ij->i", samples.n, samples.l), 0.0)
    pred = rho * np.asarray(samples.irradiance) * cos_l[:, None]
    den = float(np.sum(np.asarray(samples.radiance, dtype=np.float64) ** 2))
    return float(np.sqrt(np.sum((pred - samples.radiance) ** 2) / den)) if den > 0 else float("nan")
