"""How much light a BRDF table reflects: its directional albedo, and whether it
reflects more than it receives (energy conservation).

The directional albedo of a BRDF rho at a view direction v is
``a(v) = integral over the upper hemisphere of rho(l, v) cos(theta_l) d omega_l``:
the fraction of a uniform white sky reflected towards v (by reciprocity, also the
fraction of light arriving from v that is reflected anywhere). A physical surface
has ``a <= 1`` at every angle. A table fitted to photos can break it where no photo
looks: it may then meet every photo and still be no surface at all.
"""

from __future__ import annotations

import numpy as np

from . import merl

# The view angles (degrees from the normal) at which :func:`largest_albedo` checks
# the table: up to 80, short of grazing, where tabulated data extrapolate (the MERL
# networks beyond theta_d = 85, METHOD.md) and cos-weighted integrals carry little.
CHECK_ANGLES_DEG = np.arange(0.0, 81.0, 10.0)


def _half_vectors(n_theta: int, n_phi: int) -> tuple[np.ndarray, np.ndarray]:
    """The quadrature's half vectors (M, 3) about the normal +z, their polar angle
    spaced as the table's theta_h bins (``t^2 pi / 2``), and their solid angles
    (M,) sr; M = n_theta n_phi."""
    t = (np.arange(n_theta) + 0.5) / n_theta
    theta_h, dtheta = t * t * np.pi / 2.0, np.pi * t / n_theta
    phi = (np.arange(n_phi) + 0.5) / n_phi * 2.0 * np.pi
    th, ph = np.meshgrid(theta_h, phi, indexing="ij")
    h = np.stack([np.sin(th) * np.cos(ph), np.sin(th) * np.sin(ph), np.cos(th)],
                 axis=-1).reshape(-1, 3)
    return h, (np.sin(th) * dtheta[:, None] * (2.0 * np.pi / n_phi)).reshape(-1)


def directional_albedo(table: np.ndarray, theta_o_deg=None, n_theta: int = 120,
                       n_phi: int = 120) -> np.ndarray:
    """(A, 3) the directional albedo of ``table`` ((3, 90, 90, 180), 1/sr, RGB) for a
    viewer at each angle of ``theta_o_deg`` ((A,) degrees from the normal; default
    0.5, 1.5, ... 89.5), dimensionless.

    A quadrature over half vectors h whose polar angle is spaced as the table's
    theta_h bins (``t^2 pi / 2``, ``n_theta`` of them, ``n_phi`` azimuths), the
    light the view mirrored about h and ``d omega_l = 4 (v.h) d omega_h``, so a
    mirror's narrow lobe is integrated, not missed. Half vectors whose light is
    below the horizon add nothing. The table is read with :func:`merl.evaluate`
    (nearest cell); unmeasured (NaN) cells are filled from their neighbours
    (:func:`merl.fill_unmeasured`), infinite values count as 0."""
    theta_o = np.radians(np.arange(90) + 0.5 if theta_o_deg is None
                         else np.atleast_1d(np.asarray(theta_o_deg, dtype=np.float64)))
    h, d_omega = _half_vectors(n_theta, n_phi)
    table = np.asarray(table, dtype=np.float64)
    if np.isinf(table).any():  # on a copy: the caller's table is left as it is
        table = np.where(np.isinf(table), 0.0, table)
    if np.isnan(table).any():  # once, not per angle
        table = merl.fill_unmeasured(table)
    out = np.zeros((len(theta_o), 3))
    normal = np.array([0.0, 0.0, 1.0])
    for a, angle in enumerate(theta_o):  # one view angle at a time: (M, 3) temporaries
        v = np.array([np.sin(angle), 0.0, np.cos(angle)])
        vh = h @ v
        light = 2.0 * vh[:, None] * h - v
        ok = (vh > 0.0) & (light[:, 2] > 0.0)
        f = merl.evaluate(table, np.broadcast_to(normal, (int(ok.sum()), 3)), light[ok],
                          np.broadcast_to(v, (int(ok.sum()), 3)))
        weight = light[ok, 2] * 4.0 * vh[ok] * d_omega[ok]
        out[a] = np.nan_to_num(f, nan=0.0).T @ weight
    return out


def albedo_quadrature(theta_o_deg=CHECK_ANGLES_DEG, n_theta: int = 60,
                      n_phi: int = 60) -> tuple[np.ndarray, np.ndarray]:
    """The directional albedo as a linear map of a table's cells: ``(index, weights)``
    with ``index`` (M,) int64 the flat cells (``merl.linear_index``) the quadrature
    of :func:`directional_albedo` reads, each once, and ``weights`` (A, M) float64
    (sr) such that ``weights @ table.reshape(3, -1)[:, index].T`` is
    ``directional_albedo(table, theta_o_deg, n_theta, n_phi)`` ((A, 3)) for a finite
    table. For a fit that must keep a table's albedo in bounds (its derivative in
    the cells is ``weights``). theta_o_deg: (A,) view angles, degrees."""
    theta_o = np.radians(np.atleast_1d(np.asarray(theta_o_deg, dtype=np.float64)))
    h, d_omega = _half_vectors(n_theta, n_phi)
    normal = np.array([0.0, 0.0, 1.0])
    cells, angle_of, weight = [], [], []
    for a, angle in enumerate(theta_o):  # one view angle at a time, as directional_albedo
        v = np.array([np.sin(angle), 0.0, np.cos(angle)])
        vh = h @ v
        light = 2.0 * vh[:, None] * h - v
        ok = (vh > 0.0) & (light[:, 2] > 0.0)
        m = int(ok.sum())
        index, above = merl.lookup(np.broadcast_to(normal, (m, 3)), light[ok],
                                   np.broadcast_to(v, (m, 3)))
        cells.append(index[above])
        angle_of.append(np.full(int(above.sum()), a))
        weight.append((light[ok, 2] * 4.0 * vh[ok] * d_omega[ok])[above])
    index, inverse = np.unique(np.concatenate(cells), return_inverse=True)
    weights = np.zeros((len(theta_o), len(index)))
    np.add.at(weights, (np.concatenate(angle_of), inverse.ravel()), np.concatenate(weight))
    return index, weights


def largest_albedo(table: np.ndarray, theta_o_deg=CHECK_ANGLES_DEG) -> float:
    """The largest directional albedo of ``table`` over the view angles
    ``theta_o_deg`` (degrees) and the three channels: above 1 the table reflects
    more light than it receives there."""
    return float(np.max(directional_albedo(table, theta_o_deg)))
