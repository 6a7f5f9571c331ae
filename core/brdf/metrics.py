"""Error metrics between BRDFs and between images (METHOD.md §9)."""

from __future__ import annotations

import numpy as np

from . import merl, render


def brdf_log_rmse(estimate: np.ndarray, reference: np.ndarray) -> float:
    """Cosine-weighted log RMSE between two tables (3, 90, 90, 180) in 1/sr.

    ``sqrt(mean((ln(1 + rho_est c) - ln(1 + rho_ref c))^2))`` over the cells whose
    centre is above the horizon and that the reference measured, all channels;
    ``c = cos(theta_l) cos(theta_v)`` at the cell centre. Dimensionless.
    """
    est = np.asarray(estimate, dtype=np.float64).reshape(3, -1)
    ref = np.asarray(reference, dtype=np.float64).reshape(3, -1)
    cells = np.flatnonzero(merl.valid_cells() & np.all(np.isfinite(ref), axis=0))
    # the differences in blocks of cells (their temporaries stay in the cache), into
    # one (3, n) array laid out as ``est[:, keep]`` lays it out (cell-major), so the
    # mean adds them in the same order as the whole at once did
    d = np.empty((3, len(cells)), order="F")
    for start in range(0, len(cells), _BLOCK):
        block = slice(start, start + _BLOCK)
        idx = cells[block]
        _log_differences(est[:, idx], ref[:, idx], idx, out=d[:, block])
    return float(np.sqrt(np.mean(np.square(d, out=d))))


def log_rmse_at(estimate_at: np.ndarray, reference: np.ndarray, cells: np.ndarray) -> float:
    """:func:`brdf_log_rmse` over the flat cells ``cells`` (M,) only, for an estimate
    known there alone (a reconstruction read at some cells, without its full table).
    estimate_at: (M, 3) its values at ``cells``, 1/sr; reference: (3, 90, 90, 180).
    The cells below the horizon or that the reference did not measure are left out,
    as there. Over every cell it is :func:`brdf_log_rmse`."""
    cells = np.asarray(cells, dtype=np.int64)
    ref = np.asarray(reference, dtype=np.float64).reshape(3, -1)[:, cells]
    keep = merl.valid_cells()[cells] & np.all(np.isfinite(ref), axis=0)
    est = np.asarray(estimate_at, dtype=np.float64).T[:, keep]
    d = _log_differences(est, ref[:, keep], cells[keep])
    return float(np.sqrt(np.mean(d * d)))


def _log_differences(estimate, reference, cells, out=None) -> np.ndarray:
    """(3, M) ``ln(1 + rho_est c) - ln(1 + rho_ref c)`` at the flat cells (M,), each
    table given there as (3, M); c as in :func:`brdf_log_rmse`."""
    wi, wo = merl.cell_directions()
    c = np.clip(wi[cells, 2] * wo[cells, 2], 0.0, 1.0)
    return np.subtract(np.log1p(estimate * c), np.log1p(reference * c), out=out)


_BLOCK = 1 << 15  # cells per block of brdf_log_rmse


def relative_rmse(estimate: np.ndarray, reference: np.ndarray) -> float:
    """``||estimate - reference|| / ||reference||`` over all elements (images (H, W, 3))."""
    est = np.asarray(estimate, dtype=np.float64)
    ref = np.asarray(reference, dtype=np.float64)
    denom = np.sqrt(np.sum(ref**2))
    if denom == 0.0:
        return float(np.sqrt(np.sum(est**2)))
    return float(np.sqrt(np.sum((est - ref) ** 2)) / denom)


def _sphere_light(angle_deg: float, azimuth_deg: float) -> np.ndarray:
    a, b = np.radians(angle_deg), np.radians(azimuth_deg)
    return np.array([np.sin(a) * np.cos(b), np.sin(a) * np.sin(b), np.cos(a)])


# Evaluation lights for the rendered-sphere error, camera space (+z to the viewer):
# 20, 60 and 100 degrees between light and view, at different azimuths. They are
# not the lights the photos were taken under (those are world directions of a
# capture, seen from several cameras).
SPHERE_LIGHTS = np.array([_sphere_light(20.0, 30.0), _sphere_light(60.0, 150.0),
                          _sphere_light(100.0, 270.0)])


def sphere_error(estimate: np.ndarray, reference: np.ndarray, lights=SPHERE_LIGHTS,
                 resolution: int = 96) -> float:
    """Rendered-sphere relative RMSE of a table against the truth, under ``lights``.

    estimate, reference: (3, 90, 90, 180) tables in 1/sr. lights: (K, 3) camera-
    space directions towards the light (default :data:`SPHERE_LIGHTS`). Both
    tables are rendered on a ``resolution``-pixel sphere (``render.render_sphere``,
    irradiance 1) under every light; returns :func:`relative_rmse` of the K
    images stacked, dimensionless (0 = identical).
    """
    lights = np.atleast_2d(np.asarray(lights, dtype=np.float64))
    est = np.stack([render.render_sphere(estimate, light, resolution) for light in lights])
    ref = np.stack([render.render_sphere(reference, light, resolution) for light in lights])
    return relative_rmse(est, ref)
