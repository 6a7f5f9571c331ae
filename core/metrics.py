"""Error metrics between BRDFs and between images (METHOD.md §9)."""

from __future__ import annotations

import numpy as np

from . import merl


def brdf_log_rmse(estimate: np.ndarray, reference: np.ndarray) -> float:
    """Cosine-weighted log RMSE between two tables (3, 90, 90, 180) in 1/sr.

    ``sqrt(mean((ln(1 + rho_est c) - ln(1 + rho_ref c))^2))`` over the cells whose
    centre is above the horizon and that the reference measured, all channels;
    ``c = cos(theta_l) cos(theta_v)`` at the cell centre. Dimensionless.
    """
    wi, wo = merl.cell_directions()
    c = np.clip(wi[:, 2] * wo[:, 2], 0.0, 1.0)
    est = np.asarray(estimate, dtype=np.float64).reshape(3, -1)
    ref = np.asarray(reference, dtype=np.float64).reshape(3, -1)
    keep = merl.valid_cells() & np.all(np.isfinite(ref), axis=0)
    d = np.log1p(est[:, keep] * c[keep]) - np.log1p(ref[:, keep] * c[keep])
    return float(np.sqrt(np.mean(d**2)))


def relative_rmse(estimate: np.ndarray, reference: np.ndarray) -> float:
    """``||estimate - reference|| / ||reference||`` over all elements (images (H, W, 3))."""
    est = np.asarray(estimate, dtype=np.float64)
    ref = np.asarray(reference, dtype=np.float64)
    denom = np.sqrt(np.sum(ref**2))
    if denom == 0.0:
        return float(np.sqrt(np.sum(est**2)))
    return float(np.sqrt(np.sum((est - ref) ** 2)) / denom)
