"""Measured materials: the MERL BRDFs as Sztrajman et al. (2021) neural BRDFs.

The pack (``merl_nbrdf.npz``, see ``shared/data/README.md``) holds, per material
``m``, a 6-21-21-3 network that maps Rusinkiewicz's half and difference vectors
with ``phi_h = 0``,

    x = (sin th, 0, cos th, sin td cos pd, sin td sin pd, cos td),

to RGB reflectance in 1/sr: ``rho = exp(relu(relu(x W1 + b1) W2 + b2) W3 + b3) - 1``,
clipped at 0. :func:`tabulate` evaluates it at the MERL cell centres and returns
a table like :func:`core.brdf.merl.read` does: ``(3, 90, 90, 180)`` float64 in
1/sr, NaN where the cell's centre light or view lies below the horizon
(``merl.valid_cells``), so a pack material and a ``.binary`` file enter the basis
the same way.
"""

from __future__ import annotations

import dataclasses
import functools
import os
import pathlib

import numpy as np

from . import merl

BUNDLED_PACK = pathlib.Path(__file__).parent / "data" / "merl_nbrdf.npz"
"""The pack shipped with the extension (80 MERL materials; terms in its README)."""

# array name -> shape after the material axis (the network's layers)
_LAYERS = {"W1": (6, 21), "b1": (21,), "W2": (21, 21), "b2": (21,), "W3": (21, 3), "b3": (3,)}
_CHUNK = 1 << 17  # cells per block: the hidden layers stay at about 11 MB float32


@dataclasses.dataclass(frozen=True, eq=False)
class Pack:
    """The networks of M materials: ``names`` (M,) str and the layers' float32
    weights ``W1`` (M, 6, 21), ``b1`` (M, 21), ``W2`` (M, 21, 21), ``b2`` (M, 21),
    ``W3`` (M, 21, 3), ``b3`` (M, 3)."""

    names: tuple[str, ...]
    W1: np.ndarray
    b1: np.ndarray
    W2: np.ndarray
    b2: np.ndarray
    W3: np.ndarray
    b3: np.ndarray

    def index(self, name: str) -> int:
        """The position of material ``name``; ValueError listing a few names if absent."""
        if name not in self.names:
            raise ValueError(f"no material named {name} in the pack (it has "
                             f"{', '.join(self.names[:4])}, ... {len(self.names)} in all)")
        return self.names.index(name)


def load(path: str | os.PathLike) -> Pack:
    """Read a pack; ValueError naming the file when an array is missing, of the wrong
    shape or not finite; FileNotFoundError when there is no file."""
    path = os.fspath(path)
    try:
        z = np.load(path, allow_pickle=False)
    except (ValueError, OSError) as error:
        if isinstance(error, FileNotFoundError):
            raise
        raise ValueError(f"{path}: not a neural-BRDF pack (.npz): {error}") from None
    with z:
        missing = sorted({"names", *_LAYERS} - set(z.files))
        if missing:
            raise ValueError(f"{path}: neural-BRDF pack lacks {', '.join(missing)}")
        names = tuple(str(n) for n in z["names"])
        layers = {}
        for key, shape in _LAYERS.items():
            a = np.asarray(z[key], dtype=np.float32)
            if a.shape != (len(names), *shape):
                raise ValueError(f"{path}: {key} has shape {a.shape}, expected "
                                 f"{(len(names), *shape)}")
            if not np.all(np.isfinite(a)):
                raise ValueError(f"{path}: {key} holds NaN or Inf")
            layers[key] = a
    return Pack(names=names, **layers)


def network_input(theta_h, theta_d, phi_d) -> np.ndarray:
    """The networks' input for angles (N,) in radians: (N, 6) float32 (h, d)."""
    th, td, pd = (np.asarray(a, dtype=np.float64) for a in (theta_h, theta_d, phi_d))
    x = np.stack([np.sin(th), np.zeros_like(th), np.cos(th),
                  np.sin(td) * np.cos(pd), np.sin(td) * np.sin(pd), np.cos(td)], axis=-1)
    return x.astype(np.float32)


def evaluate(pack: Pack, m: int, theta_h, theta_d, phi_d) -> np.ndarray:
    """RGB reflectance (N, 3) float64 in 1/sr of material ``m`` at angles (N,), in
    blocks of cells (float32 inside the network, as it was trained)."""
    return _run(pack, m, network_input(theta_h, theta_d, phi_d))


def _run(pack: Pack, m: int, x: np.ndarray) -> np.ndarray:
    """The network of material ``m`` on inputs x (N, 6) float32: (N, 3) float64."""
    out = np.empty((len(x), 3), dtype=np.float64)
    for start in range(0, len(x), _CHUNK):
        a = x[start : start + _CHUNK] @ pack.W1[m]
        a += pack.b1[m]
        np.maximum(a, 0.0, out=a)
        a = a @ pack.W2[m]
        a += pack.b2[m]
        np.maximum(a, 0.0, out=a)
        z = (a @ pack.W3[m] + pack.b3[m]).astype(np.float64)
        np.expm1(z, out=z)
        out[start : start + _CHUNK] = np.maximum(z, 0.0, out=z)
    return out


@functools.lru_cache(maxsize=1)
def _valid_input() -> np.ndarray:
    """The networks' input at every valid cell centre (``merl.valid_cells()``, in
    order): (n_valid, 6) float32, 26 MB, made once."""
    cells = merl.cells_from_linear(np.flatnonzero(merl.valid_cells()))
    x = network_input(*merl.angles_from_cells(cells))
    x.flags.writeable = False
    return x


def valid_values(pack: Pack, m: int) -> np.ndarray:
    """Material ``m`` at the valid cells only, in order: (3, n_valid) float64, 1/sr,
    what :func:`tabulate` holds there."""
    return np.ascontiguousarray(_run(pack, m, _valid_input()).T)


def tabulate(pack: Pack, m: int) -> np.ndarray:
    """Material ``m`` on the MERL grid: (3, 90, 90, 180) float64, 1/sr, NaN below the
    horizon (as :func:`core.brdf.merl.read`). About 0.3 s and 35 MB."""
    table = np.full((3, merl.N_CELLS), np.nan)
    table[:, merl.valid_cells()] = valid_values(pack, m)
    return table.reshape(3, *merl.SHAPE)
