"""Optimal choice of samples: Bayes-risk or condition-number optimal (Nielsen et al.
2015, ``FewToMany``).

Two criteria score a sample set S (``criterion=``):

- ``"risk"`` (the default): the expected squared error, in the mapped space over
  every basis cell, of the ridge reconstruction that ``core.method.reconstruct``
  runs: with ``p = k`` components, the prior ``c ~ N(0, tau^2 I)``,
  ``tau^2 = 1 / n_training_columns``, and noise sigma (``noise_sigma``, log-relative
  units), the posterior covariance is ``P = (A^T A / sigma^2 + I / tau^2)^-1``
  with ``A = Q[S, :k]``, and since ``Q^T Q = diag(s^2)`` the risk is
  ``tr(diag(s^2) P)`` (a Bayesian A-optimal design weighted by the components'
  variance). Adding a row a lowers it by ``a^T P D P a / (sigma^2 + a^T P a)``.
- ``"condition"`` (the paper's, Nielsen's): the condition number of the
  acquisition matrix ``A = Q[S, :p]``, ``p = min(|S|, k)`` (METHOD.md §2).

Why the risk is the default. The reconstruction uses every component under the
prior, not the ``min(n, k)`` that the condition number looks at, and across
designs the condition number did not predict the error (Spearman about 0 over
8 seeds per fold), while the risk did (+0.65 to +0.69 within folds at n = 20).
Measured on the 5 cross-validated folds of the measured pack, seeds 0 and 1,
exact values over the whole table (``bench/measured_bench.py``), the median
sphere error of the measured basis fell from 0.200 to 0.169 at n = 6 and from 0.124
to 0.087 at n = 20 (docs/results.md, "Measured materials against the bases",
where it also loses: the analytic basis at n = 20, and n = k on analytic materials).

The search follows the reference code for both criteria:

- condition: start from the candidate whose basis row has the largest norm;
  risk: start from the prior (no sample) and add the first like the others;
- add one sample at a time, the best of 500 random candidates;
- after each addition, local search: move one sample by +-step along one grid
  axis (step 3, then 1) to another candidate, keep the best move, and stop once
  the relative improvement was <= 0.001 % three times in a row.

The condition design's greedy step scores its 500 candidates exactly, but gives an
eigendecomposition only to those a rank-one bound on the condition number cannot
rule out (``_best_addition``): the same choice, several times faster.

Unlike the reference, which searches the full grid, the candidates here are an
arbitrary set of cells (in the product: the reliable pixels of the photos), so
a move is only allowed onto another candidate. Each local search accepts at
most ``MAX_MOVES`` moves per step size: on the full grid with the built-in
basis, n = 40, the cap of 20 against 200 changed the final condition number by
under 1 % (noise of the random path) and cut the time about fourfold.
"""

from __future__ import annotations

import numpy as np

from ..brdf import merl
from ..brdf.basis import Basis

N_RANDOM = 500  # candidates tried per greedy addition
STEPS = (3, 1)  # local-search step sizes in bins
TOLERANCE = 1e-5  # relative improvement counted as "no progress"
PATIENCE = 3  # stop after this many steps without progress
MAX_MOVES = 20  # cap on accepted moves per step size and addition (see module doc)
CRITERIA = ("risk", "condition")
NOISE_SIGMA = 0.3  # log-relative units; Nielsen's eta = 40 with 450 training channels


def acquisition_condition(Q: np.ndarray, rows: np.ndarray) -> float:
    """Condition number of ``Q[rows, :p]``, p = min(len(rows), k). Inf if singular."""
    rows = np.asarray(rows)
    p = min(len(rows), Q.shape[1])
    return float(_conditions(Q[rows[None, :], :p].astype(np.float64))[0])


def design_risk(basis: Basis, rows: np.ndarray, noise_sigma: float = NOISE_SIGMA) -> float:
    """Bayes risk of the samples at basis rows (n,): ``tr(diag(s^2) P)`` (module doc),
    the expected squared mapped-space error summed over the basis cells, per channel.
    With no rows it is the prior's, ``tau^2 * sum(s^2)``."""
    _check_sigma(noise_sigma)
    rows = np.asarray(rows, dtype=np.int64)
    k = basis.n_components
    A = basis.Q[rows].astype(np.float64) / noise_sigma
    precision = A.T @ A + np.eye(k) / _prior_variance(basis)  # positive definite
    # with Lambda = L L^T: tr(D Lambda^-1) = ||L^-1 D^(1/2)||_F^2
    L = np.linalg.cholesky(precision)
    X = np.linalg.solve(L, np.diag(basis.singular_values[:k]))
    return float(np.sum(X**2))


def _prior_variance(basis: Basis) -> float:
    """tau^2 of the coefficients' prior: 1 / number of training columns (the
    training channels have coefficient vectors of unit norm, ``Q = U S``)."""
    return 1.0 / float(basis.info["n_columns"])


def _check_sigma(noise_sigma: float) -> None:
    if not (np.isfinite(noise_sigma) and noise_sigma > 0):
        raise ValueError(f"noise_sigma must be a positive number, got {noise_sigma}")


def _conditions(A: np.ndarray) -> np.ndarray:
    """Condition numbers of a stack of matrices (B, n, p) -> (B,)."""
    s = np.linalg.svd(A, compute_uv=False)
    with np.errstate(divide="ignore", invalid="ignore"):
        cond = s[:, 0] / s[:, -1]
    return np.where(np.isfinite(cond), cond, np.inf)


def candidate_rows(basis: Basis, candidate_cells: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Unique candidates that lie in the basis.

    candidate_cells: (M, 3) int bin indices. Returns (linear, rows): (U,) flat cell
    indices and their basis rows, duplicates and cells outside the basis removed.
    """
    cells = np.asarray(candidate_cells)
    if cells.ndim != 2 or cells.shape[1] != 3:
        raise ValueError(f"candidate_cells must have shape (M, 3), got {cells.shape}")
    if len(cells) and (
        (cells < 0).any() or (cells >= np.asarray(merl.SHAPE)).any()
    ):
        raise ValueError("candidate_cells hold bin indices outside (90, 90, 180)")
    linear = np.unique(merl.linear_index(cells))
    rows = basis.rows_of(linear)
    inside = rows >= 0
    return linear[inside], rows[inside]


def optimal_cells(
    basis: Basis,
    candidate_cells: np.ndarray,
    n_samples: int,
    rng: np.random.Generator | int | None = None,
    criterion: str = "risk",
    noise_sigma: float = NOISE_SIGMA,
) -> np.ndarray:
    """Choose ``n_samples`` cells among the candidates minimising the criterion.

    basis: the PCA basis. candidate_cells: (M, 3) int bin indices (any set of
    cells; duplicates and cells outside the basis are ignored). rng: Generator or
    seed; the same seed gives the same cells. criterion: "risk" (Bayes risk of the
    ridge reconstruction, the default) or "condition" (condition number of
    ``Q[S, :min(n, k)]``, the paper's); noise_sigma: the risk's noise, log-relative
    units (module doc). Returns (n, 3) int64 bin indices, n = min(n_samples, number
    of usable candidates). ValueError if none is usable or a setting is out of range.
    """
    if n_samples < 1:
        raise ValueError(f"n_samples must be at least 1, got {n_samples}")
    if criterion not in CRITERIA:
        raise ValueError(f"criterion must be one of {CRITERIA}, got {criterion!r}")
    _check_sigma(noise_sigma)
    rng = np.random.default_rng(rng)
    linear, rows = candidate_rows(basis, candidate_cells)
    if len(rows) == 0:
        raise ValueError("no candidate cell lies in the basis (all unmeasured)")
    if len(rows) <= n_samples:
        return merl.cells_from_linear(linear)
    Qc = basis.Q[rows].astype(np.float64)  # (U, k) rows of the candidates
    position = np.full(merl.N_CELLS, -1, dtype=np.int64)  # flat cell -> candidate index
    position[linear] = np.arange(len(linear))
    neighbours = _neighbour_table(merl.cells_from_linear(linear), position)
    taken = np.zeros(len(rows), dtype=bool)
    if criterion == "condition":
        chosen = _condition_design(Qc, n_samples, basis.n_components, rng, taken, neighbours)
    else:
        chosen = _risk_design(Qc / noise_sigma, n_samples, _prior_variance(basis),
                              basis.singular_values[: basis.n_components] ** 2,
                              rng, taken, neighbours)
    return merl.cells_from_linear(linear[np.asarray(chosen)])


def _condition_design(Qc, n_samples, k, rng, taken, neighbours) -> list:
    """Nielsen's greedy + local search on the condition number (module doc)."""
    chosen = [int(np.argmax(np.linalg.norm(Qc, axis=1)))]
    taken[chosen[0]] = True
    while len(chosen) < n_samples:
        p = min(len(chosen) + 1, k)
        free = np.flatnonzero(~taken)
        trial = rng.choice(free, size=min(N_RANDOM, len(free)), replace=False)
        A = Qc[np.asarray(chosen), :p]
        best = int(trial[_best_addition(A.T @ A, Qc[trial, :p])])
        chosen.append(best)
        taken[best] = True
        _local_search(chosen, taken, neighbours, _ConditionMoves(Qc[:, :p], chosen))
    return chosen


def _risk_design(Qs, n_samples, tau2, d, rng, taken, neighbours) -> list:
    """Greedy + local search on the Bayes risk. Qs: (U, k) candidate rows divided by
    sigma, so the posterior precision is ``I / tau^2 + sum a a^T``; d: (k,) s^2."""
    chosen: list = []
    moves = _RiskMoves(Qs, d, tau2)
    while len(chosen) < n_samples:
        free = np.flatnonzero(~taken)
        trial = rng.choice(free, size=min(N_RANDOM, len(free)), replace=False)
        best = int(trial[np.argmax(moves.gains(trial))])
        chosen.append(best)
        taken[best] = True
        moves.add(best)
        _local_search(chosen, taken, neighbours, moves)
    return chosen


class _ConditionMoves:
    """Scores single-sample moves by the condition number: a move replaces one row
    a_old of A by a_new, so the Gram matrix changes by ``a_new a_new^T - a_old a_old^T``;
    each candidate move is scored from that (one eigendecomposition per move)."""

    def __init__(self, Qp: np.ndarray, chosen: list):
        self.Q = Qp
        A = Qp[np.asarray(chosen)]
        self.G = A.T @ A
        self.current = _gram_conditions(self.G[None])[0]

    def evaluate(self, old: np.ndarray, new: np.ndarray) -> np.ndarray:
        o, a = self.Q[old], self.Q[new]
        self._stack = (self.G[None] + a[:, :, None] * a[:, None, :]
                       - o[:, :, None] * o[:, None, :])
        return _gram_conditions(self._stack)

    def accept(self, i: int, old: int, new: int, value: float) -> None:
        self.G = self._stack[i]
        self.current = value


class _RiskMoves:
    """The posterior of the design being built: covariance ``P = Lambda^-1`` (k, k) of
    the coefficients, risk ``tr(D P)``. Adding row a is a Sherman-Morrison update,
    ``P -= P a a^T P / (1 + a^T P a)``. A move swaps row o for row a; with
    ``U = [a, o]`` and ``C = diag(1, -1)``, Woodbury gives
    ``P -= P U M^-1 U^T P`` and the new risk ``tr(D P) - tr(M^-1 W)``,
    ``M = C^-1 + U^T P U``, ``W = U^T P D P U`` (2 x 2 each), so scoring a move costs
    O(k) once ``P a`` is known, not a k x k factorisation. The prior keeps P well
    conditioned (its eigenvalues lie in (0, tau^2]), so the updates do not drift:
    the final risk matches :func:`design_risk` (tested).

    The products are small (k = 40), so they are written as einsum, not as BLAS
    calls: on the busy 2-core machine a threaded BLAS call on a 40 x 40 matrix took
    about 10 ms (its threads wait for each other), einsum about 0.05 ms."""

    def __init__(self, Qs: np.ndarray, d: np.ndarray, tau2: float):
        k = Qs.shape[1]
        self.Q, self.d = Qs, d
        self.P = np.eye(k) * tau2
        self.current = float(np.einsum("k,kk->", d, self.P))

    def _update(self, PU: np.ndarray, Minv: np.ndarray) -> None:
        """``P -= PU Minv PU^T`` (PU: (k, r), Minv: (r, r)) and the risk with it."""
        self.P = self.P - np.einsum("ir,rs,js->ij", PU, Minv, PU)
        self.P = 0.5 * (self.P + self.P.T)
        self.current = float(np.einsum("k,kk->", self.d, self.P))

    def _weighted(self, x: np.ndarray, y: np.ndarray) -> np.ndarray:
        """Row-wise ``x^T D y`` of (B, k) stacks -> (B,)."""
        return np.einsum("bk,k,bk->b", x, self.d, y)

    def gains(self, rows: np.ndarray) -> np.ndarray:
        """Risk lowered by adding each row (T,): ``a^T P D P a / (1 + a^T P a)``."""
        a = self.Q[rows]
        Pa = np.einsum("tk,kj->tj", a, self.P)
        return self._weighted(Pa, Pa) / (1.0 + np.einsum("tk,tk->t", Pa, a))

    def add(self, row: int) -> None:
        a = self.Q[row]
        Pa = np.einsum("ij,j->i", self.P, a)
        self._update(Pa[:, None], np.array([[1.0 / (1.0 + Pa @ a)]]))

    def evaluate(self, old: np.ndarray, new: np.ndarray) -> np.ndarray:
        a, o = self.Q[new], self.Q[old]
        Pa = np.einsum("bk,kj->bj", a, self.P)
        Po = np.einsum("bk,kj->bj", o, self.P)
        m11 = 1.0 + np.einsum("bk,bk->b", a, Pa)
        m12 = np.einsum("bk,bk->b", a, Po)
        m22 = -1.0 + np.einsum("bk,bk->b", o, Po)
        det = m11 * m22 - m12**2
        with np.errstate(divide="ignore", invalid="ignore"):
            reduction = (m22 * self._weighted(Pa, Pa) - 2.0 * m12 * self._weighted(Pa, Po)
                         + m11 * self._weighted(Po, Po)) / det
        value = self.current - reduction
        return np.where(np.isfinite(value) & (value > 0), value, np.inf)

    def accept(self, i: int, old: int, new: int, value: float) -> None:
        U = np.stack([self.Q[new], self.Q[old]], axis=1)  # (k, 2)
        PU = np.einsum("ij,jr->ir", self.P, U)
        m11, m12, m22 = 1.0 + U[:, 0] @ PU[:, 0], U[:, 0] @ PU[:, 1], -1.0 + U[:, 1] @ PU[:, 1]
        det = m11 * m22 - m12**2
        self._update(PU, np.array([[m22, -m12], [-m12, m11]]) / det)


def _neighbour_table(cells: np.ndarray, position: np.ndarray) -> dict[int, np.ndarray]:
    """For each step: (U, 6) candidate index of the +-step neighbour along each axis, -1
    where that cell is not a candidate. phi_d wraps (period pi), the thetas do not."""
    table = {}
    for step in STEPS:
        cols = []
        for axis in range(3):
            for sign in (-1, 1):
                moved = cells.copy()
                moved[:, axis] += sign * step
                if axis == 2:
                    moved[:, 2] %= merl.SHAPE[2]
                    inside = np.ones(len(cells), dtype=bool)
                else:
                    inside = (moved[:, axis] >= 0) & (moved[:, axis] < merl.SHAPE[axis])
                idx = np.full(len(cells), -1, dtype=np.int64)
                idx[inside] = position[merl.linear_index(moved[inside])]
                cols.append(idx)
        table[step] = np.stack(cols, axis=1)
    return table


def _gram_conditions(G: np.ndarray) -> np.ndarray:
    """Condition numbers from a stack of Gram matrices ``A^T A`` (B, p, p) -> (B,).

    ``sqrt(lambda_max / lambda_min)``: squaring loses precision only beyond ~1e7,
    far above any set worth keeping, and it is several times cheaper than an SVD
    of each candidate set; the reported condition uses the SVD."""
    lam = np.linalg.eigvalsh(G)
    with np.errstate(divide="ignore", invalid="ignore"):
        cond = np.sqrt(lam[:, -1] / lam[:, 0])
    return np.where((lam[:, 0] > 0) & np.isfinite(cond), cond, np.inf)


def _best_addition(G: np.ndarray, new: np.ndarray) -> int:
    """Index of the row a of ``new`` (T, p) whose addition to the Gram matrix ``G``
    (p, p) leaves the lowest condition number: exactly
    ``argmin(_gram_conditions(G + a a^T))`` over the rows (the first of equal ones),
    but only the rows that a bound cannot rule out are given an eigendecomposition.

    The bound is that of a rank-one update (the secular equation, Golub 1973): with
    ``G = V diag(d) V^T`` and ``z = V^T a``, the extreme eigenvalues of ``G + a a^T``
    are roots of ``1 + sum z_i^2 / (d_i - mu)`` (:class:`_ConditionFloor`), which give
    each row a lower bound on its condition number in O(p) per step. The rows whose
    bound exceeds the exact condition of the most promising few cannot be the
    argmin; the rest are scored as before, so the choice is the same to the last
    bit (tested against scoring every row). On the demo capture (Balanced, 16 trials
    of 20 samples, 500 rows per step) the 304 greedy steps took 0.13 s against 1.25
    s (cProfile of the batch run; the demo's table the same to the bit)."""
    T, p = new.shape
    if T <= _PRUNE_FROM or p < 2:
        return int(np.argmin(_gram_conditions(_added(G, new))))
    d, V = np.linalg.eigh(G)
    floor = _ConditionFloor(d, (new @ V) ** 2)
    c_lo = floor.bound()
    first = np.argsort(c_lo, kind="stable")[:_SCORED_FIRST]
    best = np.min(_gram_conditions(_added(G, new[first])))  # an exact row's: >= the min
    kept = np.flatnonzero(~(c_lo > best))  # a NaN bound keeps its row
    for _ in range(_NEWTON_STEPS):
        if len(kept) <= _SCORED_FIRST:
            break
        floor.narrow(kept)
        kept = kept[~(floor.bound()[kept] > best)]
    return int(kept[np.argmin(_gram_conditions(_added(G, new[kept])))])


def _added(G: np.ndarray, rows: np.ndarray) -> np.ndarray:
    """The Gram matrices ``G + a a^T`` (T, p, p) for the rows a of ``rows`` (T, p)."""
    return G[None] + rows[:, :, None] * rows[:, None, :]


_PRUNE_FROM = 16  # fewer candidates than this are all scored
_SCORED_FIRST = 4  # rows scored exactly to set the bar the others' bounds must beat
_NEWTON_STEPS = 4  # tightening steps at most (each roughly doubles the digits)
_SLACK = 64  # rounding allowance on the bound's eigenvalues, in p eps ||G + a a^T||


class _ConditionFloor:
    """Lower bounds on the condition numbers of ``diag(d) + z z^T`` for a stack of z.

    d: (p,) ascending eigenvalues of G; z2: (T, p) the rows' squared components in
    G's eigenvectors. The condition is ``sqrt(mu_max / mu_min)``; a bound needs
    ``mu_max`` from below and ``mu_min`` from above, each tightened by Newton steps
    that stay on their side of the root:

    - ``mu_max = d_p + t``: ``f(t) = 1 - sum z_i^2 / (g_i + t)``, ``g_i = d_p - d_i``,
      is increasing and concave for t > 0, so Newton from below stays below. It
      starts from the Rayleigh quotients of the top eigenvector and of a.
    - ``mu_min = d_1 + t`` in ``[d_1, d_2]``: ``h(t) = t (1 + sum_{i>1} z_i^2 / (e_i - t))
      - z_1^2``, ``e_i = d_i - d_1``, is increasing and convex on [0, e_2), so Newton
      from above stays above. It starts from h's tangent at 0, or d_2.

    Rounding is allowed for by widening each eigenvalue by ``_SLACK p eps (|d|max +
    |z|^2)``: G's eigendecomposition and eigvalsh are each exact for a matrix that
    close (backward stable), far inside the allowance."""

    def __init__(self, d: np.ndarray, z2: np.ndarray):
        self.d, self.z2 = d, z2
        self.g = np.maximum(d[-1] - d, 0.0)  # (p,), g_p = 0
        self.e = np.maximum(d[1:] - d[0], 0.0)  # (p - 1,)
        total = z2.sum(axis=1)
        eps = np.finfo(np.float64).eps
        self.slack = _SLACK * len(d) * eps * (np.max(np.abs(d)) + total)
        with np.errstate(divide="ignore", invalid="ignore"):
            rayleigh = total - (z2 * self.g).sum(axis=1) / total  # a's quotient - d_p
        self.t_max = np.maximum(z2[:, -1], np.where(np.isfinite(rayleigh), rayleigh, 0.0))
        all_rows = np.arange(len(z2))
        h, dh = self._h_min(np.zeros(len(z2)), all_rows)
        with np.errstate(divide="ignore", invalid="ignore"):
            tangent = -h / dh
        self.t_min = np.minimum(np.where(np.isfinite(tangent), tangent, self.e[0]), self.e[0])

    def _h_min(self, t: np.ndarray, rows: np.ndarray):
        with np.errstate(divide="ignore", invalid="ignore"):
            gap = self.e - t[:, None]
            q = self.z2[rows, 1:] / gap
            psi, dpsi = q.sum(axis=1), (q / gap).sum(axis=1)
        return t * (1.0 + psi) - self.z2[rows, 0], 1.0 + psi + t * dpsi

    def narrow(self, rows: np.ndarray) -> None:
        """One Newton step on both roots of the given rows (indices into the stack)."""
        with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
            t = self.t_max[rows]
            gap = self.g + t[:, None]
            q = np.where(gap > 0, self.z2[rows] / gap, 0.0)
            f, df = 1.0 - q.sum(axis=1), np.where(gap > 0, q / gap, 0.0).sum(axis=1)
            step = t - f / df  # from below on a concave f: still below the root
            self.t_max[rows] = np.where(np.isfinite(step) & (step > t), step, t)
            t = self.t_min[rows]
            h, dh = self._h_min(t, rows)
            step = t - h / dh  # from above on a convex h: still above the root
            self.t_min[rows] = np.where(np.isfinite(step) & (step < t) & (step >= 0.0),
                                        step, t)

    def bound(self) -> np.ndarray:
        """(T,) lower bounds on the rows' condition numbers (inf where mu_min <= 0)."""
        top = np.maximum(self.d[-1] + self.t_max - self.slack, 0.0)
        bottom = self.d[0] + self.t_min + self.slack
        with np.errstate(divide="ignore", invalid="ignore"):
            return np.where(bottom > 0, np.sqrt(top / bottom), np.inf)


def _local_search(chosen: list, taken: np.ndarray, neighbours: dict, moves) -> None:
    """Improve ``chosen`` in place by single-sample moves to free neighbouring candidates.

    moves: the criterion's state (``_ConditionMoves`` or ``_RiskMoves``): ``current``
    value (lower is better), ``evaluate(old, new)`` the value after each move of the
    stacks (B,) of candidate indices, and ``accept(i, old, new, value)``."""
    for step in STEPS:
        quiet = 0
        for _ in range(MAX_MOVES):
            options = neighbours[step][np.asarray(chosen)]  # (n, 6)
            slot, which = np.nonzero(options >= 0)
            target = options[slot, which]
            ok = ~taken[target]
            slot, target = slot[ok], target[ok]
            if len(target) == 0:
                break
            old = np.asarray(chosen)[slot]
            value = moves.evaluate(old, target)
            i = int(np.argmin(value))
            current = moves.current
            if not value[i] < current:
                break
            gain = (current - value[i]) / current
            taken[chosen[slot[i]]] = False
            chosen[slot[i]] = int(target[i])
            taken[target[i]] = True
            moves.accept(i, int(old[i]), int(target[i]), float(value[i]))
            quiet = quiet + 1 if gain <= TOLERANCE else 0
            if quiet >= PATIENCE:
                break
