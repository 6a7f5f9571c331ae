"""The MERL tabulated isotropic BRDF: file format, half/difference angles, bins, lookup.

A table is a ``(3, 90, 90, 180)`` float64 array indexed ``(channel, theta_h bin,
theta_d bin, phi_d bin)`` holding the BRDF in 1/sr; ``NaN`` marks an unmeasured
cell. On disk (Matusik et al. 2003) a file is three little-endian int32
``(90, 90, 180)`` followed by 3 x 1,458,000 little-endian float64, one whole block
per channel (R, G, B), ``phi_d`` fastest; stored values times ``SCALE`` give 1/sr and
negative stored values mean "not measured" (METHOD.md §1).

Angles follow Rusinkiewicz (1998) in the local shading frame (normal = +z):
``h = normalize(wi + wo)``, ``theta_h = acos(h_z)``; ``d`` is ``wi`` rotated about z by
``-phi_h`` then about y by ``-theta_h``; ``theta_d = acos(d_z)``,
``phi_d = atan2(d_y, d_x)`` folded to ``[0, pi)`` by reciprocity (swapping wi and wo
adds pi to phi_d).

Bins (the reference reader): ``ith = floor(90 sqrt(theta_h / (pi/2)))``,
``itd = floor(90 theta_d / (pi/2))``, ``ipd = floor(180 phi_d / pi)``, each clamped.
A bin's representative angle, used to generate tables and for trilinear
interpolation, is its centre: ``theta_h = ((i + 0.5) / 90)^2 pi/2`` (the centre in
the square-root coordinate), ``theta_d = (i + 0.5) / 90 * pi/2``,
``phi_d = (i + 0.5) / 180 * pi``; these map back to bin ``i`` exactly.
"""

from __future__ import annotations

import functools
import os

import numpy as np

from .. import files

SHAPE = (90, 90, 180)
N_CELLS = SHAPE[0] * SHAPE[1] * SHAPE[2]  # 1,458,000 cells per channel
SCALE = np.array([1.0 / 1500.0, 1.15 / 1500.0, 1.66 / 1500.0])  # stored -> 1/sr, R G B
FILE_SIZE = 3 * 4 + 3 * N_CELLS * 8  # 34,992,012 bytes
_HALF_PI = np.pi / 2.0


# ----------------------------------------------------------------------------- file I/O
def read(path: str | os.PathLike) -> np.ndarray:
    """Read a MERL ``.binary`` file.

    Returns ``(3, 90, 90, 180)`` float64 in 1/sr, NaN where the file stores a
    negative (unmeasured) value. Raises ``ValueError`` naming the file when the
    header, the size or the values are wrong, ``FileNotFoundError`` when missing.
    """
    path = os.fspath(path)
    with open(path, "rb") as f:
        raw = f.read()
    if len(raw) < 12:
        raise ValueError(f"{path}: not a MERL BRDF file (only {len(raw)} bytes, no header)")
    dims = tuple(int(x) for x in np.frombuffer(raw[:12], dtype="<i4"))
    if dims != SHAPE:
        raise ValueError(f"{path}: MERL header gives dimensions {dims}, expected {SHAPE}")
    if len(raw) != FILE_SIZE:
        what = "truncated" if len(raw) < FILE_SIZE else "too long"
        raise ValueError(
            f"{path}: MERL file is {what}: {len(raw)} bytes, expected {FILE_SIZE}"
        )
    stored = np.frombuffer(raw, dtype="<f8", offset=12).reshape(3, *SHAPE)
    if not np.all(np.isfinite(stored)):
        raise ValueError(f"{path}: MERL file holds NaN or Inf values")
    table = stored * SCALE[:, None, None, None]
    table[stored < 0] = np.nan
    return table


def _stored_values(table: np.ndarray, out: np.ndarray | None = None) -> np.ndarray:
    """1/sr -> stored doubles, choosing for each value a stored double that reads back
    to exactly that value when one exists (the scales are not powers of two, so the
    plain quotient is sometimes one ulp off). NaN -> -1.

    table: (3, 90, 90, 180); out: (3, N_CELLS) array to write into (a new float64
    one if None), returned. Each value is converted on its own, so the work is done
    in blocks of cells whose temporaries stay in the cache."""
    flat = table.reshape(3, -1)
    if out is None:
        out = np.empty(flat.shape)
    for c in range(3):
        scale = SCALE[c]
        for start in range(0, flat.shape[1], _WRITE_BLOCK):
            block = slice(start, start + _WRITE_BLOCK)
            t = flat[c, block]
            q = t / scale
            for direction in (np.inf, -np.inf):
                miss = (q * scale != t) & np.isfinite(t)
                if not miss.any():
                    break
                alt = np.nextafter(q, direction)
                q = np.where(miss & (alt * scale == t), alt, q)
            out[c, block] = np.where(np.isnan(t), -1.0, q)
    return out


_WRITE_BLOCK = 1 << 16  # cells per block of _stored_values


def write(path: str | os.PathLike, table: np.ndarray) -> None:
    """Write a ``(3, 90, 90, 180)`` table in 1/sr to a MERL ``.binary`` file.

    NaN cells are written as -1 (unmeasured). ``read(write(t))`` reproduces ``t``
    bit for bit whenever ``t`` lies on the format's value grid (every table that
    was read from a file does) and to within one ulp otherwise. Raises
    ``ValueError`` for a wrong shape, Inf, or negative values. The file is
    written to a temporary name and renamed, so it is never left half-written.
    """
    table = np.asarray(table, dtype=np.float64)
    if table.shape != (3, *SHAPE):
        raise ValueError(f"table must have shape (3, 90, 90, 180), got {table.shape}")
    if np.isinf(table).any():
        raise ValueError("table holds Inf; a MERL file can only mark cells unmeasured (NaN)")
    if (table < 0).any():
        raise ValueError("table holds negative BRDF values")
    data = bytearray(FILE_SIZE)  # the file's bytes, filled in place (no copies)
    data[:12] = np.asarray(SHAPE, dtype="<i4").tobytes()
    _stored_values(table, np.frombuffer(data, dtype="<f8", offset=12).reshape(3, N_CELLS))
    files.write_bytes(path, data)  # a temporary name, renamed when complete


# ------------------------------------------------------------------------ angle mapping
def half_diff_from_dirs(wi: np.ndarray, wo: np.ndarray):
    """Rusinkiewicz angles of local-frame direction pairs.

    wi, wo: (N, 3) unit vectors, local frame (normal +z); wi is the light.
    Returns theta_h, theta_d, phi_d: (N,) float64 radians, phi_d folded to [0, pi).
    Defined everywhere: when wi = -wo the half vector falls back to +z.
    """
    wi = np.asarray(wi, dtype=np.float64)
    wo = np.asarray(wo, dtype=np.float64)
    h = wi + wo
    norm = np.linalg.norm(h, axis=-1, keepdims=True)
    degenerate = norm[..., 0] < 1e-12
    h = np.where(degenerate[..., None], (0.0, 0.0, 1.0), h / np.maximum(norm, 1e-300))
    theta_h = np.arccos(np.clip(h[..., 2], -1.0, 1.0))
    phi_h = np.arctan2(h[..., 1], h[..., 0])
    # d = Ry(-theta_h) Rz(-phi_h) wi
    cp, sp = np.cos(phi_h), np.sin(phi_h)
    ux = cp * wi[..., 0] + sp * wi[..., 1]
    uy = -sp * wi[..., 0] + cp * wi[..., 1]
    uz = wi[..., 2]
    ct, st = np.cos(theta_h), np.sin(theta_h)
    dx = ct * ux - st * uz
    dz = st * ux + ct * uz
    theta_d = np.arccos(np.clip(dz, -1.0, 1.0))
    phi_d = np.arctan2(uy, dx)
    phi_d = np.where(phi_d < 0.0, phi_d + np.pi, phi_d)
    phi_d = np.where(phi_d >= np.pi, 0.0, phi_d)  # -0.0 + pi rounds to pi: same direction
    return theta_h, theta_d, phi_d


def dirs_from_half_diff(theta_h, theta_d, phi_d):
    """Inverse of :func:`half_diff_from_dirs` with phi_h = 0.

    Angles: arrays (N,) radians. Returns wi, wo: (N, 3) unit vectors in the local
    frame (normal +z); directions may lie below the horizon.
    """
    theta_h, theta_d, phi_d = np.broadcast_arrays(
        *(np.asarray(a, dtype=np.float64) for a in (theta_h, theta_d, phi_d))
    )
    st_d = np.sin(theta_d)
    d = np.stack([st_d * np.cos(phi_d), st_d * np.sin(phi_d), np.cos(theta_d)], axis=-1)
    ct, st = np.cos(theta_h), np.sin(theta_h)

    def rot_y(u):  # Ry(theta_h) u
        return np.stack(
            [ct * u[..., 0] + st * u[..., 2], u[..., 1], -st * u[..., 0] + ct * u[..., 2]],
            axis=-1,
        )

    wi = rot_y(d)
    wo = rot_y(d * (-1.0, -1.0, 1.0))  # d reflected about the half vector
    return wi, wo


# Degenerate phi_d, put in bin 0 (cells_from_angles, _cells_block): phi_d within
# _PHI_WRAP of pi (the same direction pair as phi_d = 0, where l, v and the normal
# are coplanar: the rounding of a zero decides between bins 179 and 0), and any
# phi_d where theta_d is below _THETA_D_ZERO (l and v equal, as with a flash on the
# camera: phi_d is the angle of a vector of rounding noise). Otherwise the bin
# hangs on the last bit of arctan2, which differs with how numpy vectorises it.
_PHI_WRAP = 1e-9
_THETA_D_ZERO = 1e-6


def cells_from_angles(theta_h, theta_d, phi_d) -> np.ndarray:
    """Bin indices (N, 3) int64 ``(ith, itd, ipd)`` of half/difference angles (radians).

    Uses the reference reader's mapping, clamped to the grid; phi_d is folded to
    [0, pi) first, and phi_d = 0 falls in bin 0, as do phi_d within 1e-9 rad of pi
    (coplanar l, v and normal) and every phi_d of a theta_d below 1e-6 rad (l = v,
    where phi_d is undefined): the bins of those do not hang on rounding.
    """
    theta_h = np.asarray(theta_h, dtype=np.float64)
    theta_d = np.asarray(theta_d, dtype=np.float64)
    phi_d = np.mod(np.asarray(phi_d, dtype=np.float64), np.pi)
    phi_d = np.where((phi_d >= np.pi - _PHI_WRAP) | (theta_d < _THETA_D_ZERO), 0.0, phi_d)
    ith = np.floor(90.0 * np.sqrt(np.clip(theta_h, 0.0, None) / _HALF_PI))
    itd = np.floor(theta_d / _HALF_PI * 90.0)
    ipd = np.floor(phi_d / np.pi * 180.0)
    return np.stack(
        [
            np.clip(ith, 0, SHAPE[0] - 1),
            np.clip(itd, 0, SHAPE[1] - 1),
            np.clip(ipd, 0, SHAPE[2] - 1),
        ],
        axis=-1,
    ).astype(np.int64)


def angles_from_cells(cells: np.ndarray):
    """Centre angles (radians) of bins ``cells`` (N, 3) int: theta_h, theta_d, phi_d (N,)."""
    cells = np.asarray(cells)
    theta_h = ((cells[..., 0] + 0.5) / SHAPE[0]) ** 2 * _HALF_PI
    theta_d = (cells[..., 1] + 0.5) / SHAPE[1] * _HALF_PI
    phi_d = (cells[..., 2] + 0.5) / SHAPE[2] * np.pi
    return theta_h, theta_d, phi_d


def cells_from_dirs(wi: np.ndarray, wo: np.ndarray) -> np.ndarray:
    """Bin indices (N, 3) of local-frame light/view pairs (N, 3)."""
    return cells_from_angles(*half_diff_from_dirs(wi, wo))


def linear_index(cells: np.ndarray) -> np.ndarray:
    """Flat cell index ``ipd + 180 (itd + 90 ith)`` of bins (N, 3) -> (N,) int64."""
    cells = np.asarray(cells, dtype=np.int64)
    return cells[..., 2] + SHAPE[2] * (cells[..., 1] + SHAPE[1] * cells[..., 0])


def cells_from_linear(index: np.ndarray) -> np.ndarray:
    """Inverse of :func:`linear_index`: (N,) int -> (N, 3) int64."""
    return np.stack(np.unravel_index(np.asarray(index, dtype=np.int64), SHAPE), axis=-1)


@functools.lru_cache(maxsize=1)
def cell_directions():
    """Light and view directions at every cell centre, C order of (90, 90, 180).

    Returns wi, wo: (1458000, 3) float64 read-only unit vectors, local frame.
    Equal, bit for bit, to ``dirs_from_half_diff(*angles_from_cells(grid))`` over
    the grid of every cell (tested), about 10x faster: each angle's sine and cosine
    are taken once per bin (90, 90 and 180 values) and the same products are
    formed by broadcasting instead of once per cell.
    """
    bins = np.repeat(np.arange(max(SHAPE))[:, None], 3, axis=1)  # (180, 3): bin i on each axis
    theta_h, theta_d, phi_d = angles_from_cells(bins)
    theta_h, theta_d, phi_d = theta_h[:SHAPE[0]], theta_d[:SHAPE[1]], phi_d[:SHAPE[2]]
    ct = np.cos(theta_h)[:, None, None]
    st = np.sin(theta_h)[:, None, None]
    st_d = np.sin(theta_d)[None, :, None]
    d2 = np.cos(theta_d)[None, :, None]
    d0 = st_d * np.cos(phi_d)[None, None, :]
    d1 = st_d * np.sin(phi_d)[None, None, :]
    out = []
    for u0, u1, u2 in ((d0, d1, d2), (d0 * -1.0, d1 * -1.0, d2 * 1.0)):  # wi, then wo
        w = np.empty((*SHAPE, 3))  # the rotation of dirs_from_half_diff, Ry(theta_h) u
        w[..., 0] = ct * u0 + st * u2
        w[..., 1] = u1
        w[..., 2] = -st * u0 + ct * u2
        w = w.reshape(-1, 3)
        w.flags.writeable = False
        out.append(w)
    return out[0], out[1]


@functools.lru_cache(maxsize=1)
def valid_cells() -> np.ndarray:
    """(1458000,) bool, read-only: cells whose centre light and view are above the horizon."""
    wi, wo = cell_directions()
    valid = (wi[:, 2] > 0.0) & (wo[:, 2] > 0.0)
    valid.flags.writeable = False
    return valid


# ----------------------------------------------------------------------------- lookup
def fill_unmeasured(table: np.ndarray) -> np.ndarray:
    """Copy of ``table`` with NaN cells filled from the nearest measured cell.

    Filled along theta_d first (unmeasured cells sit at large theta_d, beyond the
    horizon), then along theta_h; a table with no measured cell becomes zeros.
    Used for lookups near the horizon, where a bin's centre can be below it
    while the queried directions are not.
    """
    out = np.array(table, dtype=np.float64)
    # Neither pass mixes values across the last axis (phi_d): filled in slabs of it,
    # whose temporaries stay in the cache. A slab without NaN is left as it is, which
    # is what either pass would leave of it.
    width = _FILL_SLAB if out.ndim == 4 else out.shape[-1]
    for start in range(0, out.shape[-1], width):
        slab = out[..., start:start + width]
        for axis in (2, 1):
            if not np.isnan(slab).any():
                break
            slab = _fill_along(slab, axis, reverse=False)
            slab = _fill_along(slab, axis, reverse=True)
        out[..., start:start + width] = slab
    return np.nan_to_num(out, nan=0.0, copy=False)


_FILL_SLAB = 6  # phi_d bins per slab of fill_unmeasured


def fill_unmeasured_at(table: np.ndarray, index: np.ndarray) -> np.ndarray:
    """``fill_unmeasured(table).reshape(3, -1)[:, index]`` without filling (or
    copying) the whole table: (3, N) float64 at the flat cells ``index`` (N,) int.

    Equal to it bit for bit (tested): the fill only copies values, so a measured
    cell is itself, and an unmeasured one takes, in its own theta_d column, the
    last measured cell before it, else the first after it (the two passes of the
    fill along theta_d). Only a cell whose whole column is unmeasured needs the
    theta_h pass, and then the whole table is filled.
    """
    table = np.asarray(table, dtype=np.float64)
    index = np.asarray(index, dtype=np.int64).reshape(-1)
    values = table.reshape(3, -1)[:, index]
    channel, hole = np.nonzero(np.isnan(values))
    if len(hole):
        ith, itd, ipd = np.unravel_index(index[hole], SHAPE)
        column = table[channel, ith, :, ipd]  # (H, 90): each hole's theta_d column
        measured = ~np.isnan(column)
        ramp = np.arange(SHAPE[1])
        before = np.where(measured & (ramp <= itd[:, None]), ramp, -1).max(axis=1)
        after = np.where(measured & (ramp >= itd[:, None]), ramp, SHAPE[1]).min(axis=1)
        source = np.where(before >= 0, before, after)
        if (source >= SHAPE[1]).any():  # a column with no measured cell: the theta_h pass
            return fill_unmeasured(table).reshape(3, -1)[:, index]
        values[channel, hole] = column[np.arange(len(hole)), source]
    return np.nan_to_num(values, nan=0.0)


def _fill_along(a: np.ndarray, axis: int, reverse: bool) -> np.ndarray:
    if reverse:
        a = np.flip(a, axis)
    n = a.shape[axis]
    shape = [1] * a.ndim
    shape[axis] = n
    ramp = np.arange(n).reshape(shape)
    idx = np.where(np.isnan(a), 0, ramp)
    idx = np.maximum.accumulate(idx, axis=axis)
    filled = np.take_along_axis(a, idx, axis=axis)
    filled = np.where(np.isnan(a), filled, a)
    return np.flip(filled, axis) if reverse else filled


def local_frame(n: np.ndarray):
    """Tangent and bitangent (N, 3) completing unit normals ``n`` (N, 3) to a
    right-handed orthonormal frame (Duff et al. 2017); stable for every n."""
    sign = np.where(n[..., 2] >= 0.0, 1.0, -1.0)
    a = -1.0 / (sign + n[..., 2])
    b = n[..., 0] * n[..., 1] * a
    t = np.stack([1.0 + sign * n[..., 0] ** 2 * a, sign * b, -sign * n[..., 0]], axis=-1)
    bt = np.stack([b, sign + n[..., 1] ** 2 * a, -n[..., 1]], axis=-1)
    return t, bt


def to_local(n: np.ndarray, w: np.ndarray) -> np.ndarray:
    """Express directions ``w`` (N, 3) in the local frame of normals ``n`` (N, 3)."""
    t, bt = local_frame(n)
    out = np.empty(np.broadcast_shapes(n.shape, w.shape))
    for i, axis in enumerate((t, bt, n)):
        out[..., i] = np.einsum("...i,...i->...", w, axis)
    return out


_CHUNK = 16384  # samples per block of cells_about_normals: temporaries stay in cache
# Fast-path guards of cells_about_normals (see _cells_block): a continuous theta_d or
# phi_d bin coordinate closer than _EDGE to an integer, or a difference vector
# closer than _POLE (sine) to the normal, is recomputed with the trigonometric path.
_EDGE = 1e-4
_POLE = 1e-7


def cells_about_normals(n: np.ndarray, wi: np.ndarray, wo: np.ndarray) -> np.ndarray:
    """Bin indices (N, 3) int64 of light/view pairs about unit normals, in one pass.

    n: (N, 3) unit normals; wi (light) and wo (view): (N, 3) unit vectors or one (3,)
    direction for all; all three in one common frame (world space, say). Equal, bit
    for bit, to ``cells_from_dirs(to_local(n, wi), to_local(n, wo))``, about 3x faster:
    the frame is built once for both directions, the work is done per component on
    blocks of samples, and the rotation into the half-vector frame takes its
    cosines and sines from the half vector itself (``cos phi_h = h_x / |h_xy|``,
    ``cos theta_h = h_z``, ...) instead of from the angles. Those differ from the
    trigonometric values by a few 1e-16, which moves theta_d and phi_d by far less
    than 1e-4 of a bin once d is at least 1e-7 rad from the normal, so samples
    within 1e-4 of a theta_d or phi_d bin edge, or nearer the pole, (a few in
    10^4) are recomputed with the trigonometric path of
    :func:`half_diff_from_dirs`. theta_h and its bin are computed as there.
    """
    n = np.asarray(n, dtype=np.float64)
    wi = np.asarray(wi, dtype=np.float64)
    wo = np.asarray(wo, dtype=np.float64)
    out = np.empty((len(n), 3), dtype=np.int64)
    for start in range(0, len(n), _CHUNK):
        block = slice(start, start + _CHUNK)
        nb, ib, ob = n[block].T, wi if wi.ndim == 1 else wi[block].T, \
            wo if wo.ndim == 1 else wo[block].T
        with np.errstate(invalid="ignore", divide="ignore"):  # NaN: redone exactly below
            redo = _cells_block(nb, ib, ob, out[block], exact=False)
        if len(redo):
            part = np.empty((len(redo), 3), dtype=np.int64)
            _cells_block(nb[:, redo], ib if ib.ndim == 1 else ib[:, redo],
                         ob if ob.ndim == 1 else ob[:, redo], part, exact=True)
            out[start + redo] = part
    return out


def _cells_block(n, wi, wo, out, exact):
    """cells_about_normals on one block: n, wi, wo are (3, B) (wi, wo may be (3,));
    writes (B, 3) bins into ``out``. Each line mirrors local_frame, to_local,
    half_diff_from_dirs or cells_from_angles, with the same operation order. With
    ``exact`` the rotation uses cos/sin of the angles, as half_diff_from_dirs does,
    and nothing is returned; else it uses the half vector's components and the
    indices of the samples that need the exact path are returned."""
    n0, n1, n2 = (np.ascontiguousarray(c) for c in n)
    # local_frame
    sign = np.where(n2 >= 0.0, 1.0, -1.0)
    a = np.divide(-1.0, sign + n2)
    b = n0 * n1
    b *= a
    t0 = sign * (n0 * n0)
    t0 *= a
    t0 += 1.0
    t1 = sign * b
    t2 = -sign
    t2 *= n0
    b1 = n1 * n1
    b1 *= a
    b1 += sign
    b2 = -n1
    # to_local: einsum rounds a 3-term dot product as (w0 x0 + w2 x2) + w1 x1
    ix, iy, iz = (_dot_einsum(wi, axis) for axis in ((t0, t1, t2), (b, b1, b2), (n0, n1, n2)))
    ox, oy, oz = (_dot_einsum(wo, axis) for axis in ((t0, t1, t2), (b, b1, b2), (n0, n1, n2)))
    # half_diff_from_dirs (np.linalg.norm sums as (h0^2 + h1^2) + h2^2)
    hx, hy, hz = ix + ox, iy + oy, iz + oz
    norm = hx * hx
    norm += hy * hy
    norm += hz * hz
    np.sqrt(norm, out=norm)
    degenerate = norm < 1e-12
    np.maximum(norm, 1e-300, out=norm)
    hx /= norm
    hy /= norm
    hz /= norm
    if degenerate.any():
        hx[degenerate], hy[degenerate], hz[degenerate] = 0.0, 0.0, 1.0
    np.clip(hz, -1.0, 1.0, out=hz)
    theta_h = np.arccos(hz)
    if exact:
        phi_h = np.arctan2(hy, hx, out=hy)
        cp, sp = np.cos(phi_h), np.sin(phi_h, out=phi_h)
        ct, st = np.cos(theta_h), np.sin(theta_h)
    else:  # the same cosines and sines to a few 1e-16, from h (unit) itself
        r = hx * hx
        r += hy * hy
        pole = ~(r >= 1e-300)  # h along z (or NaN): no phi_h from h
        np.sqrt(r, out=r)
        cp, sp = np.divide(hx, r, out=hx), np.divide(hy, r, out=hy)
        ct = hz
        st = np.subtract(1.0, hz, out=norm)
        st *= 1.0 + hz
        np.sqrt(st, out=st)
    ux = cp * ix
    ux += sp * iy
    uy = cp * iy
    uy -= np.multiply(sp, ix, out=sp)  # -sp ix + cp iy
    dx = ct * ux
    dx -= st * iz
    dz = np.multiply(st, ux, out=st)
    dz += np.multiply(ct, iz, out=ix)
    if not exact:
        sin_d = dx * dx  # |d_xy|^2 = sin^2 theta_d: the atan2 and arccos conditioning
        sin_d += uy * uy
        pole |= ~(sin_d >= _POLE**2)
    theta_d = np.arccos(np.clip(dz, -1.0, 1.0, out=dz), out=dz)
    phi_d = np.arctan2(uy, dx, out=uy)
    np.add(phi_d, np.pi, out=phi_d, where=phi_d < 0.0)
    np.copyto(phi_d, 0.0, where=phi_d >= np.pi)  # [0, pi): cells_from_angles' mod is a no-op
    # cells_from_angles' degenerate phi_d in bin 0
    np.copyto(phi_d, 0.0, where=(phi_d >= np.pi - _PHI_WRAP) | (theta_d < _THETA_D_ZERO))
    # cells_from_angles (theta_h = arccos(.) >= 0: its clip at 0 is a no-op too)
    ith = np.sqrt(np.divide(theta_h, _HALF_PI, out=theta_h), out=theta_h)
    ith *= 90.0
    itd = np.divide(theta_d, _HALF_PI, out=theta_d)
    itd *= 90.0
    ipd = np.divide(phi_d, np.pi, out=phi_d)
    ipd *= 180.0
    if not exact:  # bin coordinates within _EDGE of a bin edge (or NaN)
        for x, inner in ((itd, True), (ipd, False)):
            nearest = np.round(x)
            edge = np.subtract(x, nearest, out=iy)
            np.abs(edge, out=edge)
            if inner:  # theta_d: 0 and 90 are no edges (arccos >= 0; bins clip at 89)
                edge[(nearest < 1.0) | (nearest > SHAPE[1] - 1)] = 1.0
            pole |= ~(edge >= _EDGE)  # phi_d: all are (0 and 180 wrap to bins 0, 179)
    for k, x in enumerate((ith, itd, ipd)):
        out[:, k] = np.clip(np.floor(x, out=x), 0, SHAPE[k] - 1, out=x)
    return None if exact else np.flatnonzero(pole)


def _dot_einsum(w, axis):
    """Dot products of w (3, B) or (3,) with the frame axis (x0, x1, x2), each (B,),
    rounded as ``np.einsum("...i,...i->...")`` rounds them: (w0 x0 + w2 x2) + w1 x1."""
    s = w[0] * axis[0]
    s += w[2] * axis[2]
    s += w[1] * axis[1]
    return s


def evaluate(
    table: np.ndarray,
    n: np.ndarray,
    l: np.ndarray,  # noqa: E741 - the paper's name for the light direction
    v: np.ndarray,
    interpolation: str = "nearest",
) -> np.ndarray:
    """BRDF value rho(n, l, v) from a table.

    table: (3, 90, 90, 180) 1/sr (NaN = unmeasured; filled from the nearest
    measured cell). n, l, v: (N, 3) unit vectors in one common frame (world
    space, say); l points to the light, v to the viewer. Any float dtype.
    interpolation: "nearest" (the reference reader's bins) or "trilinear"
    (between bin centres; phi_d wraps with period pi).
    Returns (N, 3) float64 in 1/sr, zero where n.l <= 0 or n.v <= 0; finite.
    """
    table = np.asarray(table, dtype=np.float64)
    if table.shape != (3, *SHAPE):
        raise ValueError(f"table must have shape (3, 90, 90, 180), got {table.shape}")
    n, l, v = (np.asarray(x, dtype=np.float64).reshape(-1, 3) for x in (n, l, v))
    if not (len(n) == len(l) == len(v)):
        raise ValueError("n, l and v must have the same number of rows")
    if interpolation not in ("nearest", "trilinear"):
        raise ValueError(f"interpolation must be 'nearest' or 'trilinear', got {interpolation!r}")
    if np.isnan(table).any():
        table = fill_unmeasured(table)
    flat = table.reshape(3, -1)
    if interpolation == "nearest":
        index, above = lookup(n, l, v)
        return lookup_values(flat[:, index].T, above)
    angles, above = _half_diff_about(n, l, v)
    return lookup_values(_trilinear(flat, *angles), above)


def lookup(n: np.ndarray, l: np.ndarray, v: np.ndarray):  # noqa: E741
    """The nearest cells of rho(n, l, v): (N,) int64 flat cell index of each
    direction pair and (N,) bool ``above`` (n.l > 0 and n.v > 0). n, l, v: (N, 3)
    float64 unit vectors in one frame. ``evaluate(..., "nearest")`` is
    ``lookup_values(table.reshape(3, -1)[:, index].T, above)``; a caller that
    evaluates many tables at the same directions looks them up once."""
    angles, above = _half_diff_about(n, l, v)
    return linear_index(cells_from_angles(*angles)), above


def _half_diff_about(n, l, v):  # noqa: E741
    """Rusinkiewicz angles of (l, v) about n, and (N,) bool n.l > 0 and n.v > 0."""
    wi = to_local(n, l)
    wo = to_local(n, v)
    return half_diff_from_dirs(wi, wo), (wi[:, 2] > 0.0) & (wo[:, 2] > 0.0)


def lookup_values(rho: np.ndarray, above: np.ndarray) -> np.ndarray:
    """rho (N, 3) looked up at a direction pair's cell -> (N, 3) float64, zero below
    the horizon (``above`` False) and where the table held NaN or +Inf."""
    return np.where(above[:, None], np.nan_to_num(rho, nan=0.0, posinf=0.0), 0.0)


def _trilinear(flat: np.ndarray, theta_h, theta_d, phi_d) -> np.ndarray:
    # Continuous coordinates with bin centres at integers.
    x = 90.0 * np.sqrt(np.clip(theta_h, 0.0, _HALF_PI) / _HALF_PI) - 0.5
    y = 90.0 * np.clip(theta_d, 0.0, _HALF_PI) / _HALF_PI - 0.5
    z = 180.0 * np.mod(phi_d, np.pi) / np.pi - 0.5
    x = np.clip(x, 0.0, SHAPE[0] - 1.0)
    y = np.clip(y, 0.0, SHAPE[1] - 1.0)
    x0 = np.minimum(np.floor(x).astype(np.int64), SHAPE[0] - 2)
    y0 = np.minimum(np.floor(y).astype(np.int64), SHAPE[1] - 2)
    z0f = np.floor(z)
    fx, fy, fz = x - x0, y - y0, z - z0f
    z0 = np.mod(z0f.astype(np.int64), SHAPE[2])
    z1 = np.mod(z0 + 1, SHAPE[2])
    out = np.zeros((len(x), 3))
    for dx, wx in ((0, 1.0 - fx), (1, fx)):
        for dy, wy in ((0, 1.0 - fy), (1, fy)):
            for zi, wz in ((z0, 1.0 - fz), (z1, fz)):
                idx = zi + SHAPE[2] * ((y0 + dy) + SHAPE[1] * (x0 + dx))
                out += (wx * wy * wz)[:, None] * flat[:, idx].T
    return out
