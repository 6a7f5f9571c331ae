"""Optimal sampling (core.method.sampling) on the built-in basis: the Bayes-risk and the
condition-number designs against random cells, the risk's formula against a Monte-Carlo
run of the ridge model, seeding, few candidates, ill-conditioned candidate sets and
out-of-range settings."""

import numpy as np
import pytest

from brdf_reconstruct.core.brdf import merl, metrics
from brdf_reconstruct.core.method import reconstruct, sampling


def _observe(table, cells):
    return table.reshape(3, -1)[:, merl.linear_index(cells)].T


def _all_cells(B):
    return merl.cells_from_linear(B.cells)


def _rows(B, cells):
    return B.rows_of(merl.linear_index(cells))


def _error_cells(B, every: int = 16) -> np.ndarray:
    """(M,) flat cells: a fixed draw of 1 in ``every`` of the basis' cells."""
    rng = np.random.default_rng(0)
    return np.sort(rng.choice(B.cells, len(B.cells) // every, replace=False))


def _log_rmse_at(rec, truth, at) -> float:
    """``metrics.log_rmse_at`` of a reconstruction, read at the cells ``at`` (flat)
    from its coefficients (``rho_at``), without its full table."""
    return metrics.log_rmse_at(rec.rho_at(at), truth, at)


def test_the_error_draw_reads_the_tables_error(default_basis, heldout_tables):
    """The fixed 1-in-16 draw of cells (``_error_cells``) reads a reconstruction's
    ``metrics.brdf_log_rmse`` (reference: its expanded table) to within 3 % (measured:
    1.0 % for the gold, 1.0 % or less for five other held-out materials)."""
    B = default_basis
    truth = heldout_tables["heldout_gold_medium"]
    cells = sampling.optimal_cells(B, _all_cells(B), 20, 0)
    rec = reconstruct.reconstruct(B, cells, _observe(truth, cells))
    whole = metrics.brdf_log_rmse(rec.table, truth)
    assert _log_rmse_at(rec, truth, _error_cells(B)) == pytest.approx(whole, rel=0.03)


# ------------------------------------------------------------- optimal against random
def test_optimal_sampling_beats_random_at_every_n_from_5(default_basis, heldout_tables):
    """For each criterion, the optimal design against random cells: the median criterion
    (the one the design minimised) and the median BRDF-space error (the cosine-weighted
    log RMSE of ``metrics.brdf_log_rmse``, read at a fixed draw of 1 in 16 of the
    table's cells, ``metrics.log_rmse_at``, so that no table is expanded) over the held-out
    materials and two seeds. The rendered-sphere error is reported by
    bench/core_bench.py."""
    B = default_basis
    cand = _all_cells(B)
    at = _error_cells(B)
    value = {"risk": lambda c: sampling.design_risk(B, _rows(B, c)),
             "condition": lambda c: sampling.acquisition_condition(B.Q, _rows(B, c))}
    for n in (5, 10, 20, 40):
        cells = {m: [] for m in (*sampling.CRITERIA, "random")}
        for seed in (0, 1):
            rng = np.random.default_rng(seed)
            for criterion in sampling.CRITERIA:
                cells[criterion].append(
                    sampling.optimal_cells(B, cand, n, seed, criterion=criterion))
            cells["random"].append(cand[rng.choice(len(cand), n, replace=False)])
        errors = {m: np.median([_log_rmse_at(
            reconstruct.reconstruct(B, c, _observe(truth, c)), truth, at)
            for c in sets for truth in heldout_tables.values()]) for m, sets in cells.items()}
        for criterion in sampling.CRITERIA:
            assert (np.median([value[criterion](c) for c in cells[criterion]])
                    < np.median([value[criterion](c) for c in cells["random"]])), (criterion, n)
            assert errors[criterion] < errors["random"], (criterion, n, errors)


def test_risk_design_has_lower_risk_than_the_condition_design(default_basis):
    """Each criterion wins on its own score: the risk design's Bayes risk is below the
    condition design's, and the condition design's condition number below the risk
    design's (the two criteria differ), at n = 6 and 20, same seed."""
    B = default_basis
    cand = _all_cells(B)
    for n in (6, 20):
        risk = sampling.optimal_cells(B, cand, n, 0, criterion="risk")
        cond = sampling.optimal_cells(B, cand, n, 0, criterion="condition")
        assert sampling.design_risk(B, _rows(B, risk)) < sampling.design_risk(B, _rows(B, cond))
        assert (sampling.acquisition_condition(B.Q, _rows(B, cond))
                < sampling.acquisition_condition(B.Q, _rows(B, risk)))


def test_design_risk_is_the_expected_error_of_the_ridge_model(default_basis):
    """Independent check of the formula: draw coefficients from the prior
    c ~ N(0, tau^2 I), observe b = A c + N(0, sigma^2), solve the ridge (posterior mean)
    written out here, and average ||Q (c - c_hat)||^2 over the whole basis; it must
    match tr(diag(s^2) P) to Monte-Carlo precision (4000 draws: about 2 %)."""
    B = default_basis
    sigma, n = 0.3, 8
    rng = np.random.default_rng(5)
    rows = rng.choice(len(B.cells), n, replace=False)
    k = B.n_components
    tau2 = 1.0 / B.info["n_columns"]
    Q = B.Q.astype(np.float64)
    A = Q[rows]
    c = rng.normal(0.0, np.sqrt(tau2), (k, 4000))
    b = A @ c + rng.normal(0.0, sigma, (n, 4000))
    c_hat = np.linalg.solve(A.T @ A + (sigma**2 / tau2) * np.eye(k), A.T @ b)
    gram = Q.T @ Q  # diag(s^2) up to float32 rounding
    err = c - c_hat
    empirical = np.mean(np.einsum("ij,ik,kj->j", err, gram, err))
    assert sampling.design_risk(B, rows, sigma) == pytest.approx(empirical, rel=0.06)
    assert sampling.design_risk(B, rows[:0], sigma) == pytest.approx(
        tau2 * np.sum(B.singular_values[:k] ** 2), rel=1e-9)


# ------------------------------------------------------------- seeds, edges, settings
@pytest.mark.parametrize("criterion", sampling.CRITERIA)
def test_optimal_cells_seeded_and_drawn_from_candidates(default_basis, criterion):
    B = default_basis
    rng = np.random.default_rng(3)
    cand = _all_cells(B)[rng.choice(len(B.cells), 5000, replace=False)]
    a = sampling.optimal_cells(B, cand, 12, np.random.default_rng(7), criterion=criterion)
    b = sampling.optimal_cells(B, cand, 12, 7, criterion=criterion)
    np.testing.assert_array_equal(a, b)
    assert len(np.unique(merl.linear_index(a))) == 12
    assert set(merl.linear_index(a)) <= set(merl.linear_index(cand))


@pytest.mark.parametrize("criterion", sampling.CRITERIA)
def test_optimal_cells_with_few_candidates_returns_them(default_basis, criterion):
    cand = _all_cells(default_basis)[:3]
    cand = np.concatenate([cand, cand[:1]])  # a duplicate
    got = sampling.optimal_cells(default_basis, cand, 10, 0, criterion=criterion)
    assert sorted(merl.linear_index(got)) == sorted(set(merl.linear_index(cand)))
    with pytest.raises(ValueError, match="basis"):
        # theta_h = theta_d = 89 deg, phi_d = 0: below the horizon, never in the basis
        sampling.optimal_cells(default_basis, np.array([[89, 89, 0]]), 2, 0,
                               criterion=criterion)


def test_risk_design_on_an_ill_conditioned_candidate_set(default_basis, heldout_tables):
    """Candidates in one 3 x 3 x 3 block of neighbouring cells: their rows are nearly
    alike, so any 10 of them are ill-conditioned (condition number above 1e6). The
    prior keeps the risk finite; the design still returns 10 distinct candidates and
    the reconstruction from them is finite."""
    B = default_basis
    axes = (np.arange(30, 33), np.arange(10, 13), np.arange(90, 93))
    block = np.stack(np.meshgrid(*axes, indexing="ij"), axis=-1).reshape(-1, 3)
    cells = sampling.optimal_cells(B, block, 10, 0)
    assert len(np.unique(merl.linear_index(cells))) == 10
    assert set(merl.linear_index(cells)) <= set(merl.linear_index(block))
    rows = _rows(B, cells)
    assert np.isfinite(sampling.design_risk(B, rows))
    assert sampling.acquisition_condition(B.Q, rows) > 1e6  # it is ill-conditioned
    truth = next(iter(heldout_tables.values()))
    rec = reconstruct.reconstruct(B, cells, _observe(truth, cells))
    assert np.all(np.isfinite(rec.table))


@pytest.mark.parametrize("setting, message", [
    ({"criterion": "entropy"}, "criterion"),
    ({"noise_sigma": 0.0}, "noise_sigma"),
    ({"noise_sigma": float("nan")}, "noise_sigma"),
    ({"noise_sigma": -1.0}, "noise_sigma"),
])
def test_optimal_cells_refuses_out_of_range_settings(default_basis, setting, message):
    with pytest.raises(ValueError, match=message):
        sampling.optimal_cells(default_basis, _all_cells(default_basis)[:100], 5, 0, **setting)


def test_risk_updates_do_not_drift(default_basis):
    """The design keeps its posterior by rank-1 and rank-2 updates (Sherman-Morrison,
    Woodbury); after 30 additions and 30 swaps its risk still equals the one
    refactorised from scratch (design_risk) to 1e-9."""
    B = default_basis
    rng = np.random.default_rng(11)
    rows = rng.choice(len(B.cells), 60, replace=False)
    sigma = sampling.NOISE_SIGMA
    moves = sampling._RiskMoves(B.Q[rows].astype(np.float64) / sigma,
                                B.singular_values[: B.n_components] ** 2,
                                1.0 / B.info["n_columns"])
    chosen = list(range(30))
    for i in chosen:
        moves.add(i)
    for j in range(30, 60):  # swap slot j - 30 for candidate j
        value = moves.evaluate(np.array([chosen[j - 30]]), np.array([j]))[0]
        moves.accept(0, chosen[j - 30], j, value)
        chosen[j - 30] = j
        assert moves.current == pytest.approx(value, rel=1e-9)
    assert moves.current == pytest.approx(sampling.design_risk(B, rows[chosen], sigma), rel=1e-9)


# ------------------------------------------------- the greedy step's pruned scoring
def _stacks():
    """Gram matrices and candidate rows the greedy step meets, and worse: G of a
    square-short A (one zero eigenvalue, the greedy step's own case), of a full A, at
    scales 1e-8 and 1e6, with duplicate, zero, parallel and near-singular rows."""
    rng = np.random.default_rng(5)
    for p in (2, 3, 8, 20, 40):
        for scale in (1e-8, 1.0, 1e6):
            for m in (p - 1, 2 * p):
                A = rng.normal(size=(m, p)) * scale
                new = rng.normal(size=(300, p)) * scale
                new[10] = new[200]  # a tie: the first of the two must win
                new[11] = 0.0
                new[12] = A[0]  # parallel to a row already in
                new[13] = A[0] * (1 + 1e-12)
                new[14:40] *= rng.uniform(1e-6, 1e3, (26, 1))
                yield A.T @ A, new
    # an ill-conditioned design: rows nearly in one plane
    base = rng.normal(size=(2, 12))
    A = rng.normal(size=(11, 2)) @ base + 1e-7 * rng.normal(size=(11, 12))
    yield A.T @ A, rng.normal(size=(500, 2)) @ base + 1e-5 * rng.normal(size=(500, 12))


def test_the_greedy_steps_pruning_chooses_the_row_scoring_every_row_would():
    """The condition design's greedy step bounds each candidate's condition by the
    secular equation and scores only the rows the bound cannot rule out; its choice
    must be the brute-force argmin, to the row (the first of equal ones), on every
    stack above; and on the well-conditioned ones it must spare most rows their
    eigendecomposition (the point of it)."""
    scored = []

    def counting(G):
        scored.append(len(G))
        return every_row(G)

    every_row = sampling._gram_conditions
    checked = offered = 0
    for G, new in _stacks():
        every = every_row(G[None] + new[:, :, None] * new[:, None, :])
        with pytest.MonkeyPatch.context() as patch:
            patch.setattr(sampling, "_gram_conditions", counting)
            assert sampling._best_addition(G, new) == int(np.argmin(every))
        checked += 1
        offered += len(new) if checked <= 30 else 0
        if checked == 30:
            assert sum(scored) < 0.15 * offered, (sum(scored), offered)
    assert checked == 31


def test_the_condition_floor_is_below_every_rows_condition():
    """The bound the pruning rests on: at its start and after each Newton step, no
    row's lower bound exceeds its condition number from eigvalsh."""
    for G, new in _stacks():
        every = sampling._gram_conditions(G[None] + new[:, :, None] * new[:, None, :])
        d, V = np.linalg.eigh(G)
        floor = sampling._ConditionFloor(d, (new @ V) ** 2)
        rows = np.arange(len(new))
        for _ in range(6):
            bound = floor.bound()
            assert not np.any(bound > every * (1 + 1e-12)), np.max(bound / every)
            floor.narrow(rows)
