"""Fit the bake's lobe model (:mod:`.lobes`) to a tabulated BRDF.

The fit (:func:`fit`) minimises, over a fixed subsample of the measured cells,
the residual ``sqrt(c) [ln(c rho_model + eps) - ln(c rho_table + eps)]`` with
``c = cos_l cos_v``: log space, so a 1e4 mirror peak and a dark diffuse weigh
alike; ``c`` is the weight a cell carries into images (radiance is
``rho cos_l E``, and a normal seen at ``theta_v`` covers ``cos_v`` of a pixel's
share; Nielsen et al. 2015 map with the same product); ``eps = EPS_REL x`` the
median ``c rho`` of the table, so cells far darker than the material's typical
(off-peak) level do not steer the fit, yet a dark diffuse under a bright peak
still does. Starts: every pair of (distribution, roughness) on a log grid (and
each velvet width), with colours solved in closed form (non-negative least squares on the
linearised, relative residual); the best few are polished together by a
projected Levenberg-Marquardt. Deterministic, no random numbers.
"""

from __future__ import annotations

import dataclasses
import itertools
import json
import time

import numpy as np

from ..brdf import merl, metrics, render
from .lobes import (
    ALPHA_MAX,
    ALPHA_MIN,
    DISTRIBUTIONS,
    INV_PI,
    MAX_LOBES,
    SIGMA_MAX,
    SIGMA_MIN,
    Geometry,
    LobeParams,
    tabulate,
)

EPS_REL = 0.1
ALPHA_GRID = np.geomspace(ALPHA_MIN, ALPHA_MAX, 22)
SIGMA_GRID = np.geomspace(0.1, SIGMA_MAX, 5)
N_POLISH = 3  # best grid starts, polished together for SHORT_POLISH steps
SHORT_POLISH = 12
LONG_POLISH = 40  # steps for the best of them
# Lights (camera space, +z to the viewer) for the fit's own sphere errors:
# the reference light, a head-on light and two near-grazing ones.
ERROR_LIGHTS = np.array([
    render.REFERENCE_LIGHT,
    [0.0, 0.0, 1.0],
    [-0.8, 0.2, 0.5657],
    [0.3, -0.9, 0.3162],
])
_FIT_STRIDE = (1, 4, 8)  # subsample of the (theta_h, theta_d, phi_d) bins: ~33k cells
_MIN_CELLS = 2000


@dataclasses.dataclass(frozen=True, eq=False)  # arrays: no element-wise ==
class LobeFit:
    """Result of :func:`fit`.

    params: the fitted :class:`LobeParams`. errors: see :func:`fit_errors`, plus
    ``fit_loss`` (RMS of the fit's own weighted log residual on its cells).
    info: ``n_cells`` used, ``eps``, ``n_lobes``, ``sheen``, ``time_fit_s`` and
    ``time_total_s`` (seconds; the total includes the error evaluation).
    """

    params: LobeParams
    errors: dict
    info: dict

    def to_json(self) -> str:
        return json.dumps({"params": self.params.to_dict(), "errors": self.errors,
                           "info": self.info}, sort_keys=True)


# ----------------------------------------------------------------------------- fitting
def clean_table(table, copy: bool = True) -> np.ndarray:
    """(3, 90, 90, 180) float64 copy of a table given as (3, 90, 90, 180) or
    (90, 90, 180, 3), NaN where unmeasured (NaN, Inf or negative). ValueError
    for another shape. ``copy=False``: the table itself (or a view of it) when it
    is already a clean float64 table, for callers that only read it."""
    t = np.asarray(table)
    if t.shape == (*merl.SHAPE, 3):
        t = np.moveaxis(t, -1, 0)
    if t.shape != (3, *merl.SHAPE):
        raise ValueError(
            f"table must have shape (3, 90, 90, 180) or (90, 90, 180, 3), got {np.shape(table)}"
        )
    given = t
    t = np.asarray(t, dtype=np.float64)
    bad = np.isinf(t) | (t < 0.0)  # NaN is unmeasured already
    damaged = bool(bad.any())
    if (copy or damaged) and np.may_share_memory(t, given):  # else a converted copy
        t = np.array(t)
    if damaged:
        t[bad] = np.nan
    return t


def _fit_cells(t: np.ndarray) -> np.ndarray:
    """Flat indices of the cells the fit uses: measured (all three channels),
    centre above the horizon, on a fixed stride of the grid that keeps every
    theta_h bin (dense at the specular peak); all measured cells if the stride
    leaves fewer than _MIN_CELLS."""
    measured = merl.valid_cells() & np.all(np.isfinite(t.reshape(3, -1)), axis=0)
    grid = np.zeros(merl.SHAPE, dtype=bool)
    sh, sd, sp = _FIT_STRIDE
    grid[::sh, sd // 2::sd, sp // 2::sp] = True
    idx = np.flatnonzero(grid.ravel() & measured)
    if len(idx) < _MIN_CELLS:
        idx = np.flatnonzero(measured)
    if len(idx) == 0:
        raise ValueError("table has no measured cell above the horizon: nothing to fit")
    return idx


def _log_floor(energy):
    """eps of the log residual: EPS_REL x the median cosine-weighted value, so a
    dark diffuse under a bright peak still counts (the median cell is off-peak);
    floored for tables that are zero almost everywhere."""
    return max(EPS_REL * float(np.median(energy)), 1e-8 * float(np.max(energy)), 1e-300)


class _Problem:
    """The weighted log residual on the fit cells, and its normal equations.

    Parameter vector x: kd (3), A (K x 3), B (K), C (3, with sheen), then the
    non-linear ln alpha (K) and ln sigma (with sheen). Bounds: colours >= 0,
    B in [0, 1], alpha in [ALPHA_MIN, 1], sigma in [SIGMA_MIN, 1].
    """

    def __init__(self, geo, rho, dists, sheen):
        self.geo = geo
        self.dists = tuple(dists)
        n_lobes = len(self.dists)
        cos = self.geo.cos_l * self.geo.cos_v
        self.c = cos[:, None]
        self.sw = np.sqrt(cos)[:, None]
        self.target = rho
        energy = self.c * rho
        self.eps = _log_floor(energy)
        self.log_target = np.log(energy + self.eps)
        k = self.k = n_lobes
        self.sheen = bool(sheen)
        ns = int(self.sheen)
        self.n_lin = 3 + 4 * k + 3 * self.sheen
        self.n_par = self.n_lin + k + self.sheen
        inf = np.inf
        self.lower = np.concatenate([np.zeros(self.n_lin), np.full(k, np.log(ALPHA_MIN)),
                                     np.full(ns, np.log(SIGMA_MIN))])
        self.upper = np.concatenate([np.full(3 + 3 * k, inf), np.ones(k),
                                     np.full(3 * ns, inf),
                                     np.full(k, np.log(ALPHA_MAX)),
                                     np.full(ns, np.log(SIGMA_MAX))])

    def unpack(self, x):
        k = self.k
        kd = x[:3]
        colors = x[3:3 + 3 * k].reshape(k, 3)
        grazing = x[3 + 3 * k:3 + 4 * k]
        sheen = x[3 + 4 * k:self.n_lin] if self.sheen else np.zeros(3)
        alphas = np.exp(x[self.n_lin:self.n_lin + k])
        sigma = float(np.exp(x[-1])) if self.sheen else 0.5
        return kd, colors, grazing, sheen, alphas, sigma

    def pack(self, kd, colors, grazing, sheen, alphas, sigma):
        parts = [kd, np.ravel(colors), grazing]
        if self.sheen:
            parts.append(sheen)
        parts.append(np.log(alphas))
        if self.sheen:
            parts.append([np.log(sigma)])
        return np.concatenate([np.asarray(p, dtype=np.float64).ravel() for p in parts])

    def model(self, x):
        """Model values (N, 3), microfacet shapes and velvet shape at x (last result cached:
        the optimiser asks for the residual and then the normal equations at the
        same point)."""
        cached = getattr(self, "_model_cache", None)
        if cached is not None and np.array_equal(cached[0], x):
            return cached[1]
        kd, colors, grazing, sheen, alphas, sigma = self.unpack(x)
        shapes = [self.geo.microfacet(d, a) for d, a in zip(self.dists, alphas, strict=True)]
        velvet = self.geo.velvet(sigma) if self.sheen else None
        # kd / pi + sum_k shape_k (A_k + B_k schlick) (+ velvet C), summed per channel
        # along contiguous rows, then laid out (N, 3) as the residual expects
        m = np.empty((3, len(self.target)))
        m[:] = (kd * INV_PI)[:, None]
        for s, a, b in zip(shapes, colors, grazing, strict=True):
            rise = b * self.geo.schlick
            for ch in range(3):
                m[ch] += s * (a[ch] + rise)
        if self.sheen:
            for ch in range(3):
                m[ch] += velvet * sheen[ch]
        m = np.ascontiguousarray(m.T)
        self._model_cache = (np.array(x), (m, shapes, velvet))
        return m, shapes, velvet

    def residual(self, x):
        m = self.model(x)[0]
        return (self.sw * (np.log(self.c * m + self.eps) - self.log_target)).ravel()

    def normal_equations(self, x, r):
        """J'J (P, P) and J'r (P,) at x, r = residual(x), without forming the tall
        Jacobian: channel c depends only on kd_c, A_kc, B_k, C_c and the widths."""
        kd, colors, grazing, sheen, alphas, sigma = self.unpack(x)
        m, shapes, velvet = self.model(x)
        g = self.sw * self.c / (self.c * m + self.eps)  # (N, 3): d r / d rho_model
        k, geo, n_lin = self.k, self.geo, self.n_lin
        dshapes = [geo.microfacet_dlog(d, a) for d, a in zip(self.dists, alphas, strict=True)]
        dvelvet = geo.velvet_dlog(sigma) if self.sheen else None
        hess = np.zeros((self.n_par, self.n_par))
        grad = np.zeros(self.n_par)
        r = r.reshape(-1, 3)
        # Columns of d r / d x for one channel: the same for all three channels first
        # (Lambert, the lobes' shapes and Schlick terms, the velvet), stacked once,
        # then the widths' columns, which carry the channel's colours.
        same = [np.full(len(m), INV_PI), *shapes, *(s * geo.schlick for s in shapes)]
        if self.sheen:
            same.append(velvet)
        same = np.stack(same, axis=1)
        n_same = same.shape[1]
        for ch in range(3):
            idx = [ch, *(3 + 3 * i + ch for i in range(k)), *(3 + 3 * k + i for i in range(k))]
            if self.sheen:
                idx.append(3 + 4 * k + ch)
            own = [(colors[i, ch] + grazing[i] * geo.schlick) * dshapes[i] for i in range(k)]
            idx += [n_lin + i for i in range(k)]
            if self.sheen:
                own.append(sheen[ch] * dvelvet)
                idx.append(n_lin + k)
            # a = [same, own] * g[:, ch], written in place (the values and the layout of
            # np.stack(columns, axis=1) * g[:, ch:ch + 1])
            a = np.empty((len(m), n_same + len(own)))
            gc = g[:, ch:ch + 1]
            np.multiply(same, gc, out=a[:, :n_same])
            for j, col in enumerate(own):
                np.multiply(col, gc[:, 0], out=a[:, n_same + j])
            idx = np.array(idx)
            hess[np.ix_(idx, idx)] += a.T @ a
            grad[idx] += a.T @ r[:, ch]
        return hess, grad

    def loss(self, x):
        r = self.residual(x)
        return float(np.sqrt(np.mean(r * r)))


def _nnls_from_gram(gram, rhs, labels=None):
    """Non-negative least squares from normal equations, exhaustively over the
    active sets. gram: (B, m, m), rhs: (B, m), a batch of tiny problems (m <= 6).
    Returns beta (B, m) >= 0 minimising beta'G beta - 2 beta'b, and that value (B,).

    labels: optional (B, m) ints such that two problems whose labels agree on an
    active set have the same gram and rhs there (the grid's combinations share
    lobes): each distinct system is then solved once and its solution given to all
    that share it, which is the solution each would get on its own."""
    batch, m = rhs.shape
    best = np.zeros((batch, m))
    best_val = np.zeros(batch)  # beta = 0
    shared = _SharedSystems(labels) if labels is not None else None
    for size in range(1, m + 1):
        ridge = 1e-12 * np.eye(size)
        for subset in itertools.combinations(range(m), size):
            s = np.array(subset)
            b = rhs[:, s]
            first, inverse = shared.of(s) if shared is not None else (slice(None), None)
            g = gram[first][:, s[:, None], s[None, :]]
            g += ridge
            beta = _solve_symmetric(g, rhs[first][:, s])
            if inverse is not None:
                beta = beta[inverse]
            val = -np.einsum("bi,bi->b", beta, b)  # at the optimum b'Gb - 2b'b = -b'b
            # a singular system (non-finite beta) is no candidate
            better = np.flatnonzero(np.all(beta >= 0.0, axis=1) & np.all(np.isfinite(beta), axis=1)
                                    & (val < best_val))
            best[better] = 0.0
            best[better[:, None], s[None, :]] = beta[better]
            best_val[better] = val[better]
    return best, best_val


def _solve_symmetric(gram, rhs):
    """Solve a batch of small symmetric positive definite systems: gram (B, m, m),
    rhs (B, m) -> x (B, m). Gaussian elimination without pivoting (stable for a
    positive definite matrix), vectorised over the batch: numpy's stacked solve
    calls LAPACK once per matrix, which for m <= 6 costs 10 to 20x more than the
    arithmetic. Each problem's arithmetic is its own, so a problem's solution does
    not depend on the batch it is in. A singular system gives non-finite entries
    (no exception)."""
    a = np.array(np.moveaxis(gram, 0, -1), dtype=np.float64)  # (m, m, B): rows of B
    y = np.array(rhs.T, dtype=np.float64)  # (m, B)
    m = len(y)
    with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
        for j in range(m):
            f = a[j + 1:, j] / a[j, j]  # (m - j - 1, B)
            a[j + 1:, j + 1:] -= f[:, None, :] * a[None, j, j + 1:]
            y[j + 1:] -= f * y[j]
        x = np.empty_like(y)
        for j in reversed(range(m)):
            x[j] = (y[j] - np.sum(a[j, j + 1:] * x[j + 1:], axis=0)) / a[j, j]
    return x.T


class _SharedSystems:
    """Which problems of :func:`_nnls_from_gram` share their system on an active set:
    those whose labels agree there. Label columns that are equal (a lobe's shape and
    its Schlick term) count once, so the grouping is found once per set of distinct
    columns, not once per active set."""

    def __init__(self, labels):
        labels = np.asarray(labels, dtype=np.int64)
        self.labels = labels - labels.min(axis=0)
        m = labels.shape[1]
        self.canonical = [next(q for q in range(p + 1)
                               if np.array_equal(self.labels[:, q], self.labels[:, p]))
                          for p in range(m)]
        self.groups = {}

    def of(self, subset):
        """(first, inverse): one problem of each group and each problem's group."""
        key = tuple(sorted({self.canonical[p] for p in subset}))
        if key not in self.groups:
            packed = np.zeros(len(self.labels), dtype=np.int64)
            for p in key:  # mixed radix: distinct labels, distinct numbers
                radix = int(self.labels[:, p].max()) + 1
                if packed.max(initial=0) >= (2**62) // radix:  # would overflow: no sharing
                    self.groups[key] = (slice(None), None)
                    break
                packed = packed * radix + self.labels[:, p]
            else:
                _, first, inverse = np.unique(packed, return_index=True, return_inverse=True)
                self.groups[key] = (first, inverse.reshape(-1))
        return self.groups[key]


def _grid_starts(geo: Geometry, rho: np.ndarray, n_lobes: int, sheen: bool):
    """Starting points: every set of ``n_lobes`` (distribution, width) from
    DISTRIBUTIONS x ALPHA_GRID (and each SIGMA_GRID velvet width), colours solved per
    channel in closed form on the linearised residual. Returns the best N_POLISH as
    (problem, x0) pairs; each problem has its lobes' distributions."""
    base = _Problem(geo, rho, ("ggx",) * n_lobes, sheen)  # its weights and eps
    k = n_lobes
    lobes = [(d, a) for d in DISTRIBUTIONS for a in ALPHA_GRID]
    n_l = len(lobes)
    sigmas = SIGMA_GRID if sheen else np.zeros(0)
    micro = np.stack([geo.microfacet(d, a) for d, a in lobes], axis=1)  # (N, L)
    columns = [np.full((len(micro), 1), INV_PI), micro, micro * geo.schlick[:, None]]
    columns += [np.stack([geo.velvet(s) for s in sigmas], axis=1)] if sheen else []
    basis = np.concatenate(columns, axis=1)
    # Linearised log residual: sqrt(c) c (rho_m - rho_t) / (c rho_t + eps).
    w2 = (base.sw * base.c / (base.c * rho + base.eps)) ** 2
    weighted = np.empty_like(basis)  # one buffer for the three channels' weighted basis
    grams = np.stack([np.multiply(basis, w2[:, ch:ch + 1], out=weighted).T @ basis
                      for ch in range(3)])
    rhs = (w2 * rho).T @ basis  # (3, columns)
    sets = np.array(list(itertools.combinations(range(n_l), k)), dtype=int)
    if k == 0:
        sets = np.zeros((1, 0), dtype=int)  # one "combination": no lobe
    n_s = max(len(sigmas), 1)
    combos = np.repeat(sets, n_s, axis=0)
    sig_idx = np.tile(np.arange(n_s), len(sets))
    cols = [np.zeros((len(combos), 1), dtype=int), 1 + combos, 1 + n_l + combos]
    if sheen:
        cols.append((1 + 2 * n_l + sig_idx)[:, None])
    cols = np.concatenate(cols, axis=1)
    # One batch of (combination, channel) problems.
    gram = grams[:, cols[:, :, None], cols[:, None, :]].transpose(1, 0, 2, 3)  # (C, 3, m, m)
    b = rhs[:, cols].transpose(1, 0, 2)  # (C, 3, m)
    # The system of an active set depends on the channel and on the lobes and velvet
    # width of the columns in it only (the labels of _nnls_from_gram).
    factors = [np.zeros((len(combos), 1), dtype=int), combos, combos]
    if sheen:
        factors.append(sig_idx[:, None])
    factors = np.concatenate(factors, axis=1)  # (C, m): which lobe / width a column is
    labels = factors[:, None, :] * 3 + np.arange(3)[None, :, None]  # (C, 3, m)
    beta, val = _nnls_from_gram(gram.reshape(-1, *gram.shape[2:]), b.reshape(-1, b.shape[2]),
                                labels.reshape(-1, labels.shape[2]))
    betas = beta.reshape(b.shape)
    total = val.reshape(len(cols), 3).sum(axis=1)
    starts = []
    for i in np.argsort(total, kind="stable")[:N_POLISH]:
        bi = betas[i]
        problem = _Problem(geo, rho, tuple(lobes[j][0] for j in combos[i]), sheen)
        x0 = problem.pack(bi[:, 0], bi[:, 1:1 + k].T,
                          np.clip(bi[:, 1 + k:1 + 2 * k].mean(axis=0), 0.0, 1.0),
                          bi[:, -1] if sheen else None,
                          np.array([lobes[j][1] for j in combos[i]]),
                          sigmas[sig_idx[i]] if sheen else None)
        starts.append((problem, x0))
    return starts


def _polish(problem: _Problem, x0, max_iter: int):
    """Projected Levenberg-Marquardt within the bounds. Normal equations of at most
    17 unknowns: a step costs one residual and one pass for J'J, no factorisation
    of the tall Jacobian."""
    lo, hi = problem.lower, problem.upper
    x = np.clip(x0, lo, hi)
    r = problem.residual(x)
    cost = float(r @ r)
    lam = 1e-3
    for _ in range(max_iter):
        hess, grad = problem.normal_equations(x, r)
        # Variables pushed against a bound by the gradient stay there this step.
        free = ~(((x <= lo) & (grad > 0.0)) | ((x >= hi) & (grad < 0.0)))
        if not free.any():
            break
        h = hess[np.ix_(free, free)]
        d = np.diag(np.maximum(np.diag(h), 1e-30))
        improved = False
        while lam < 1e12:
            step = np.zeros_like(x)
            try:
                step[free] = -np.linalg.solve(h + lam * d, grad[free])
            except np.linalg.LinAlgError:
                lam *= 10.0
                continue
            x_new = np.clip(x + step, lo, hi)
            r_new = problem.residual(x_new)
            cost_new = float(r_new @ r_new)
            if cost_new < cost:
                improved = True
                break
            lam *= 4.0
        if not improved:
            break
        gain = cost - cost_new
        x, r, cost = x_new, r_new, cost_new
        lam = max(lam / 3.0, 1e-9)
        if gain <= 1e-7 * cost:  # the loss is settled to far below its meaning
            break
    return x


def fit(table, n_lobes: int = 2, sheen: bool = True, errors: bool = True) -> LobeFit:
    """Fit Lambert + ``n_lobes`` microfacet lobes (+ a velvet sheen) to a table.

    table: (3, 90, 90, 180) (core.brdf.merl layout) or (90, 90, 180, 3), any float
    dtype, BRDF in 1/sr; NaN, Inf and negative cells count as unmeasured and are
    ignored. n_lobes: 0, 1 or 2. sheen: fit the velvet lobe too. errors: also
    compute :func:`fit_errors` (about 0.3 s; without, ``errors`` holds only
    ``fit_loss``). Returns a :class:`LobeFit` with finite parameters;
    deterministic. The fit takes 0.4-1.5 s on two shared cores
    (``info["time_fit_s"]``, ``info["time_total_s"]``). Raises ValueError for a
    wrong shape, a bad n_lobes, or a table with no measured cell.
    """
    if n_lobes not in range(MAX_LOBES + 1):
        raise ValueError(f"n_lobes must be 0, 1 or 2, got {n_lobes!r}")
    t0 = time.perf_counter()
    t = clean_table(table, copy=False)
    idx = _fit_cells(t)
    l, v = merl.dirs_from_half_diff(*merl.angles_from_cells(merl.cells_from_linear(idx)))
    rho = t.reshape(3, -1)[:, idx].T
    geo = Geometry(l, v)
    if not np.any(rho > 0.0):  # black: nothing to fit, and log space has no scale
        problem = _Problem(geo, rho, ("ggx",) * n_lobes, sheen)
        best_x = np.clip(np.zeros(problem.n_par), problem.lower, problem.upper)
    else:
        # A short polish of every start, then the best one to convergence.
        polished = [(p, _polish(p, x0, SHORT_POLISH)) for p, x0 in _grid_starts(geo, rho, n_lobes,
                                                                                 sheen)]
        problem, best_x = min(polished, key=lambda px: px[0].loss(px[1]))
        best_x = _polish(problem, best_x, LONG_POLISH)
    best_loss = problem.loss(best_x)
    kd, colors, grazing, sheen_color, alphas, sigma = problem.unpack(best_x)
    order = np.argsort(alphas, kind="stable")  # sharpest lobe first
    params = LobeParams(kd.copy(), colors[order].copy(), grazing[order].copy(),
                        alphas[order].copy(), np.array(sheen_color, dtype=np.float64), sigma,
                        tuple(problem.dists[i] for i in order))
    t_fit = time.perf_counter() - t0
    errs = _errors(params, t) if errors else {}
    errs["fit_loss"] = float(best_loss)
    info = {"n_cells": len(idx), "eps": float(problem.eps), "n_lobes": n_lobes,
            "sheen": bool(sheen), "time_fit_s": t_fit, "time_total_s": time.perf_counter() - t0}
    return LobeFit(params, errs, info)


def fit_errors(params, table, resolution: int = 64) -> dict:
    """Errors of the model against a table (same layouts as :func:`fit`).

    Returns ``log_rmse`` (:func:`metrics.brdf_log_rmse`, ln(1 + rho cos_l cos_v),
    measured cells only), ``sphere_rel_rmse`` (relative RMSE of
    :func:`render.render_sphere` images under ``REFERENCE_LIGHT``) and
    ``sphere_rel_rmse_lights`` (one per ``ERROR_LIGHTS`` row; the first is the
    reference light). The model is tabulated at the cell centres, so both images
    go through the same bin lookup and the numbers are the bake's error alone.
    """
    return _errors(params, clean_table(table, copy=False), resolution)


def _errors(params, t: np.ndarray, resolution: int = 64) -> dict:
    """:func:`fit_errors` of a clean table ``t`` (:func:`clean_table`). The spheres are
    those of ``render.render_sphere(merl.fill_unmeasured(x), light, resolution)``,
    bit for bit (tested), but each light's pixels are looked up once for both
    tables and only the looked-up cells are filled (``merl.fill_unmeasured_at``),
    not two whole tables."""
    model = tabulate(params)
    log_rmse = metrics.brdf_log_rmse(model, t)
    looked_up = [_sphere_lookup(light, resolution) for light in ERROR_LIGHTS]
    index = np.concatenate([lookup[1] for lookup in looked_up])
    ends = np.cumsum([len(lookup[1]) for lookup in looked_up])[:-1]
    values = [np.split(merl.fill_unmeasured_at(x, index), ends, axis=1) for x in (model, t)]
    per_light = []
    for (mask, _index, above, cos), model_values, table_values in zip(looked_up, *values,
                                                                       strict=True):
        per_light.append(metrics.relative_rmse(_sphere_image(model_values, mask, above, cos),
                                               _sphere_image(table_values, mask, above, cos)))
    return {"log_rmse": float(log_rmse), "sphere_rel_rmse": float(per_light[0]),
            "sphere_rel_rmse_lights": [float(e) for e in per_light]}


def _sphere_lookup(light, resolution: int):
    """What ``render.render_sphere(table, light, resolution)`` looks up, for any table:
    the sphere's mask (H, W), the nearest cell (N,) and ``above`` (N,) of each pixel
    inside it, and its light cosine (N,); the same steps as ``render.shade`` and
    ``merl.evaluate`` take."""
    light = np.asarray(light, dtype=np.float64)
    light = light / np.linalg.norm(light)
    normals, mask = render.sphere_normals(resolution)
    n = np.asarray(normals[mask], dtype=np.float64).reshape(-1, 3)
    l = np.broadcast_to(light, n.shape)  # noqa: E741
    v = np.broadcast_to(np.asarray((0.0, 0.0, 1.0), dtype=np.float64), n.shape)
    index, above = merl.lookup(*(x.reshape(-1, 3) for x in (n, l, v)))
    cos = np.clip(np.sum(n * l, axis=1), 0.0, None)
    return mask, index, above, cos


def _sphere_image(values: np.ndarray, mask, above, cos) -> np.ndarray:
    """The sphere image of :func:`_sphere_lookup` from a table's (filled) values
    (3, N) at its cells (irradiance 1)."""
    image = np.zeros((*mask.shape, 3))
    image[mask] = merl.lookup_values(values.T, above) * cos[:, None]
    return image
