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
        new = Qc[trial, :p]
        cond = _gram_conditions((A.T @ A)[None] + new[:, :, None] * new[:, None, :])
        best = int(trial[np.argmin(cond)])
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
