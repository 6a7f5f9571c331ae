"""Nielsen et al. (2015) PCA basis of tabulated BRDFs in the log-relative mapping.

Training data (METHOD.md §2): every BRDF channel is one column over the MERL
cells. At each cell, with ``c = cos(theta_l) cos(theta_v)`` clipped to
``[0.01, 1]`` and ``m`` the median over the training columns of ``rho * c``,

    x = ln((rho c + eps) / (m + eps)),  eps = 0.001.

The per-cell mean of ``x`` is removed and the centred matrix (rows = cells,
columns = training channels) is decomposed, ``D = U S V^T``. The scaled basis
``Q = U S`` (cells x k, the first k components) is kept.

The basis is built from a stream of tables (the built-in analytic database of
:mod:`.database`, or a folder of the user's MERL files) in blocks of cells, in
float32 where that is safe, and cached on disk keyed by a fingerprint of the
data and the settings, so a changed database always rebuilds.
"""

from __future__ import annotations

import dataclasses
import hashlib
import json
import os
import pathlib
import tempfile
import time
from collections.abc import Iterable

import numpy as np

from ..progress import CancelCheck, Progress, check, report
from . import merl

EPS = 1e-3  # Nielsen's eps in the log-relative mapping
COSINE_CLIP = 0.01  # lower clip of the cosine map
N_COMPONENTS = 40  # components kept by default: 1.1 M cells x 40 x 4 B = 175 MB cached
FORMAT_VERSION = 1  # bump when the cache layout or the mapping changes
_BLOCK = 1 << 16  # cells per block while building


@dataclasses.dataclass(frozen=True)
class Basis:
    """A PCA basis over the cells that every training table measured.

    Attributes (R = number of basis cells, k = number of components):
      cells: (R,) int64 flat MERL cell index (see ``merl.linear_index``), ascending.
      Q: (R, k) float32 scaled principal directions ``U S``, log-relative units.
      mean: (R,) float32 per-cell mean of the mapped training data.
      median: (R,) float32 per-cell median of the cosine-weighted training data, 1/sr.
      cosine: (R,) float32 cosine map ``c`` at the cell centres, clipped.
      singular_values: (k,) float64 ``S`` (all of them up to k).
      x_range: (2,) float64 min and max of the mapped training data (for clipping).
      fingerprint: hex digest of the data and settings the basis was built from.
      info: build statistics (columns, seconds, peak bytes, explained variance).
    """

    cells: np.ndarray
    Q: np.ndarray
    mean: np.ndarray
    median: np.ndarray
    cosine: np.ndarray
    singular_values: np.ndarray
    x_range: np.ndarray
    fingerprint: str
    info: dict
    # lookups derived from ``cells`` on first use (row of each cell, fill source)
    _derived: dict = dataclasses.field(default_factory=dict, repr=False, compare=False)

    @property
    def n_components(self) -> int:
        return self.Q.shape[1]

    def rows_of(self, linear: np.ndarray) -> np.ndarray:
        """Basis row of each flat cell index (N,) -> (N,) int64, -1 if not in the basis."""
        lut = _row_lookup(self)
        return lut[np.asarray(linear, dtype=np.int64)].astype(np.int64)

    def to_mapped(self, rho: np.ndarray, rows: np.ndarray) -> np.ndarray:
        """Log-relative mapping of rho (N, ...) in 1/sr at basis rows (N,)."""
        c = self.cosine[rows].astype(np.float64)
        m = self.median[rows].astype(np.float64)
        shape = (-1,) + (1,) * (np.ndim(rho) - 1)
        rho = np.maximum(rho, 0.0)
        return np.log((rho * c.reshape(shape) + EPS) / (m.reshape(shape) + EPS))

    def from_mapped(self, x: np.ndarray, rows: np.ndarray | slice = slice(None)) -> np.ndarray:
        """Inverse mapping: x (N, ...) at basis rows -> rho (N, ...) in 1/sr, >= 0, finite."""
        c = self.cosine[rows].astype(np.float64)
        m = self.median[rows].astype(np.float64)
        shape = (-1,) + (1,) * (np.ndim(x) - 1)
        lo, hi = self.x_range
        margin = 5.0  # allow extrapolation by e^5 beyond anything seen in training
        x = np.clip(x, lo - margin, hi + margin)
        rho = (np.exp(x) * (m.reshape(shape) + EPS) - EPS) / c.reshape(shape)
        return np.maximum(rho, 0.0)

    def table_from_rows(self, values: np.ndarray) -> np.ndarray:
        """Per-row RGB values (R, 3) as a full table (3, 90, 90, 180): cells outside the
        basis take the value of the basis cell ``merl.fill_unmeasured`` would copy."""
        return np.ascontiguousarray(values.T[:, _fill_source(self)]).reshape(3, *merl.SHAPE)

    def project(self, table: np.ndarray, n_components: int | None = None) -> np.ndarray:
        """Best approximation of ``table`` (3, 90, 90, 180) in the basis span (least
        squares in the mapped space over all basis cells): the projection floor.
        Returns a full, finite table."""
        k = self.n_components if n_components is None else int(n_components)
        rho = np.asarray(table, dtype=np.float64).reshape(3, -1)[:, self.cells].T  # (R, 3)
        x = self.to_mapped(np.nan_to_num(rho, nan=0.0), np.arange(len(self.cells)))
        b = x - self.mean.astype(np.float64)[:, None]
        Q = self.Q[:, :k].astype(np.float64)
        coef = np.linalg.solve(Q.T @ Q, Q.T @ b)
        x_hat = Q @ coef + self.mean.astype(np.float64)[:, None]
        return self.table_from_rows(self.from_mapped(x_hat))


def _row_lookup(basis: Basis) -> np.ndarray:
    """(1458000,) int32 basis row of each cell, -1 outside the basis."""
    lut = basis._derived.get("rows")
    if lut is None:
        lut = np.full(merl.N_CELLS, -1, dtype=np.int32)
        lut[basis.cells] = np.arange(len(basis.cells), dtype=np.int32)
        basis._derived["rows"] = lut
    return lut


def _fill_source(basis: Basis) -> np.ndarray:
    """(1458000,) basis row that each cell takes its value from (itself if inside)."""
    src = basis._derived.get("fill")
    if src is None:
        rows = np.full(merl.N_CELLS, np.nan)
        rows[basis.cells] = np.arange(len(basis.cells))
        src = merl.fill_unmeasured(rows.reshape(1, *merl.SHAPE)).reshape(-1).astype(np.int64)
        basis._derived["fill"] = src
    return src


def cosine_map() -> np.ndarray:
    """(1458000,) float64 ``cos(theta_l) cos(theta_v)`` at cell centres, clipped to
    [0.01, 1]."""
    wi, wo = merl.cell_directions()
    return np.clip(wi[:, 2] * wo[:, 2], COSINE_CLIP, 1.0)


def settings_key(n_components: int) -> dict:
    return {
        "eps": EPS,
        "cosine_clip": COSINE_CLIP,
        "n_components": int(n_components),
        "format": FORMAT_VERSION,
    }


def build(
    tables: Iterable[np.ndarray],
    n_components: int = N_COMPONENTS,
    fingerprint: str = "",
    progress: Progress | None = None,
    cancelled: CancelCheck | None = None,
    n_tables: int | None = None,
) -> Basis:
    """Build a basis from a stream of tables.

    tables: iterable of (3, 90, 90, 180) arrays in 1/sr (NaN = unmeasured); each
    contributes three columns. Only cells above the horizon at their centre and
    measured in every table are kept. n_components: k, capped by the number of
    columns. progress: optional ``progress(fraction, message)`` (``core.progress``),
    called after every table and every block of cells, so at least once a second
    on the built-in database; n_tables: the stream's length, for its fractions.
    cancelled: optional callable checked as often; True raises
    ``core.progress.Cancelled`` (nothing is kept).
    Memory: one float32 value per (column, cell): 0.44 GB per 100 channels.
    """
    t0 = time.perf_counter()

    def stage(fraction: float, message: str) -> None:
        check(cancelled)
        report(progress, fraction, message)

    # reading or generating the tables is most of the time: 80 %, the passes 20 %
    of_tables = f"/{n_tables}" if n_tables else ""
    geo = np.flatnonzero(merl.valid_cells())
    n_blocks = -(-len(geo) // _BLOCK)  # at most; the kept cells are fewer
    cos = cosine_map()[geo].astype(np.float32)
    # (n_cols, n_geo) float32, cosine-weighted: filled in place when the stream's
    # length is known (no second copy at the end), else gathered and joined
    X = np.empty((3 * n_tables, len(geo)), dtype=np.float32) if n_tables else None
    columns: list[np.ndarray] = []
    keep = np.ones(len(geo), dtype=bool)
    n_done = 0
    for i, table in enumerate(tables):
        table = np.asarray(table)
        if table.shape != (3, *merl.SHAPE):
            raise ValueError(f"training table {i} has shape {table.shape}, not (3, 90, 90, 180)")
        if X is not None and i >= n_tables:
            raise ValueError(f"more training tables than the {n_tables} announced")
        rho = table.reshape(3, -1)[:, geo]
        keep &= np.all(np.isfinite(rho) & (rho >= 0), axis=0)
        if X is not None:
            np.multiply(rho, cos, out=X[3 * i : 3 * i + 3], casting="same_kind")
        else:
            columns.append((rho * cos).astype(np.float32))
        n_done = i + 1
        stage(0.8 * (n_done / n_tables) if n_tables else 0.0,
              f"building the BRDF basis (once): table {n_done}{of_tables}")
    if n_done == 0:
        raise ValueError("no training tables given")
    X = X[: 3 * n_done] if X is not None else np.concatenate(columns, axis=0)
    del columns
    n_cols = X.shape[0]
    rows = np.flatnonzero(keep)
    if len(rows) < n_cols:
        raise ValueError(f"only {len(rows)} cells are measured in every training table")

    median = np.empty(len(rows), dtype=np.float32)
    mean = np.empty(len(rows), dtype=np.float32)
    gram = np.zeros((n_cols, n_cols))
    x_lo, x_hi = np.inf, -np.inf
    # Pass 1, per block of cells: median, mapping, mean, centring (in place), Gram.
    for b, start in enumerate(range(0, len(rows), _BLOCK)):
        stage(0.8 + 0.1 * b / n_blocks, "building the BRDF basis (once): principal "
              f"components, block {b + 1}/{n_blocks}")
        r = rows[start : start + _BLOCK]
        x = X[:, r].astype(np.float64)
        # the median along contiguous rows (twice as fast as along the strided axis,
        # the same values); the mapping in place (the same operations, no temporaries)
        m = np.median(np.ascontiguousarray(x.T), axis=1)
        x += EPS
        x /= m + EPS
        np.log(x, out=x)
        x_lo, x_hi = min(x_lo, x.min()), max(x_hi, x.max())
        mu = x.mean(axis=0)
        x -= mu
        gram += x @ x.T
        X[:, r] = x
        median[start : start + len(r)] = m
        mean[start : start + len(r)] = mu
    # D^T D = V S^2 V^T, so Q = U S = D V.
    eigval, V = np.linalg.eigh(gram)
    order = np.argsort(eigval)[::-1]
    eigval = np.clip(eigval[order], 0.0, None)
    V = V[:, order]
    k = int(min(n_components, n_cols))
    Vk = V[:, :k].astype(np.float32)
    Q = np.empty((len(rows), k), dtype=np.float32)
    for b, start in enumerate(range(0, len(rows), _BLOCK)):
        stage(0.9 + 0.1 * b / n_blocks, "building the BRDF basis (once): basis vectors, "
              f"block {b + 1}/{n_blocks}")
        r = rows[start : start + _BLOCK]
        Q[start : start + len(r)] = X[:, r].T @ Vk
    del X
    stage(1.0, "building the BRDF basis (once): done")
    total = float(eigval.sum())
    info = {
        "n_columns": int(n_cols),
        "n_cells": int(len(rows)),
        "n_components": k,
        "explained_variance": float(eigval[:k].sum() / total) if total > 0 else 1.0,
        "build_seconds": time.perf_counter() - t0,
    }
    return Basis(
        cells=geo[rows].astype(np.int64),
        Q=Q,
        mean=mean,
        median=median,
        cosine=cos[rows],
        singular_values=np.sqrt(eigval[:k]),
        x_range=np.array([x_lo, x_hi]),
        fingerprint=fingerprint,
        info=info,
    )


# ------------------------------------------------------------------------------- cache
def default_cache_dir() -> pathlib.Path:
    """``$BRDF_RECONSTRUCT_CACHE`` or ``~/.cache/brdf_reconstruct``. Blender passes its
    extension user directory instead."""
    env = os.environ.get("BRDF_RECONSTRUCT_CACHE")
    if env:
        return pathlib.Path(env)
    return pathlib.Path(os.path.expanduser("~")) / ".cache" / "brdf_reconstruct"


def save(basis: Basis, path: str | os.PathLike) -> None:
    """Write atomically (temporary file, then rename) as an uncompressed ``.npz``."""
    path = pathlib.Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(dir=path.parent, suffix=".tmp.npz")
    os.close(fd)
    try:
        np.savez(
            tmp,
            cells=basis.cells,
            Q=basis.Q,
            mean=basis.mean,
            median=basis.median,
            cosine=basis.cosine,
            singular_values=basis.singular_values,
            x_range=basis.x_range,
            fingerprint=np.array(basis.fingerprint),
            info=np.array(json.dumps(basis.info)),
        )
        os.replace(tmp, path)
    finally:
        if os.path.exists(tmp):
            os.remove(tmp)


def load(path: str | os.PathLike) -> Basis:
    """Read a basis written by :func:`save`."""
    with np.load(os.fspath(path)) as z:
        return Basis(
            cells=z["cells"],
            Q=z["Q"],
            mean=z["mean"],
            median=z["median"],
            cosine=z["cosine"],
            singular_values=z["singular_values"],
            x_range=z["x_range"],
            fingerprint=str(z["fingerprint"]),
            info=json.loads(str(z["info"])),
        )


def _cached(fingerprint: str, make, cache_dir) -> Basis:
    cache_dir = default_cache_dir() if cache_dir is None else pathlib.Path(cache_dir)
    path = cache_dir / f"basis-{fingerprint[:24]}.npz"
    if path.exists():
        try:
            basis = load(path)
            if basis.fingerprint == fingerprint:
                return basis
        except (OSError, ValueError, KeyError):
            pass  # a damaged cache file is rebuilt, never trusted
    basis = make()
    save(basis, path)
    return basis


def _fingerprint(data_key: str, n_components: int) -> str:
    text = json.dumps({"data": data_key, "settings": settings_key(n_components)}, sort_keys=True)
    return hashlib.blake2b(text.encode(), digest_size=20).hexdigest()


def load_default(
    cache_dir: str | os.PathLike | None = None,
    n_components: int = N_COMPONENTS,
    progress: Progress | None = None,
    cancelled: CancelCheck | None = None,
) -> Basis:
    """The built-in basis from the analytic database, built and cached on first use.
    progress, cancelled: as in :func:`build` (used only when it builds)."""
    from . import database

    specs = database.training_specs()
    fp = _fingerprint(database.database_fingerprint(specs), n_components)
    return _cached(
        fp,
        lambda: build(
            (database.make_table(s) for s in specs), n_components, fp, progress=progress,
            cancelled=cancelled, n_tables=len(specs),
        ),
        cache_dir,
    )


def merl_folder_files(folder: str | os.PathLike) -> list[pathlib.Path]:
    """The ``*.binary`` files of a folder, sorted; ValueError if there are none."""
    folder = pathlib.Path(folder)
    if not folder.is_dir():
        raise ValueError(f"BRDF database folder {folder} does not exist")
    files = sorted(folder.glob("*.binary"))
    if not files:
        raise ValueError(f"BRDF database folder {folder} holds no MERL .binary files")
    return files


def load_merl_folder(
    folder: str | os.PathLike,
    cache_dir: str | os.PathLike | None = None,
    n_components: int = N_COMPONENTS,
    progress: Progress | None = None,
    cancelled: CancelCheck | None = None,
) -> Basis:
    """A basis from the user's MERL ``.binary`` files, cached under a hash of their
    names and contents (about 1 s per 30 files to hash). progress, cancelled: as in
    :func:`build` (used only when it builds)."""
    files = merl_folder_files(folder)
    h = hashlib.blake2b(digest_size=20)
    for f in files:
        h.update(f.name.encode())
        with open(f, "rb") as fh:
            for chunk in iter(lambda fh=fh: fh.read(1 << 22), b""):
                h.update(chunk)
    fp = _fingerprint("merl:" + h.hexdigest(), n_components)
    return _cached(
        fp,
        lambda: build((merl.read(f) for f in files), n_components, fp, progress=progress,
                      cancelled=cancelled, n_tables=len(files)),
        cache_dir,
    )


def _pack_key(path: pathlib.Path, names: tuple[str, ...]) -> str:
    """The pack file's content hash and the materials taken from it."""
    h = hashlib.blake2b(path.read_bytes(), digest_size=20)
    h.update("\n".join(names).encode())
    return h.hexdigest()


def _pack_basis(pack_path, names, analytic: bool, cache_dir, n_components, progress,
                cancelled) -> Basis:
    """The pack's materials ``names`` (default: all), after the built-in analytic
    database when ``analytic``; built by :func:`build` and cached under the pack's
    content hash and the names (and the database's fingerprint)."""
    from . import database, nbrdf

    pack = nbrdf.load(pack_path)
    chosen = tuple(pack.names if names is None else names)
    if not chosen:
        raise ValueError("no measured materials chosen for the basis")
    for name in chosen:
        pack.index(name)  # ValueError naming an unknown material
    specs = database.training_specs() if analytic else []
    key = _pack_key(pathlib.Path(pack_path), chosen)
    data = f"union:{database.database_fingerprint(specs)}:{key}" if analytic else f"measured:{key}"
    fp = _fingerprint(data, n_components)

    def tables():
        yield from (database.make_table(s) for s in specs)
        yield from (nbrdf.tabulate(pack, pack.index(n)) for n in chosen)

    return _cached(fp, lambda: build(tables(), n_components, fp, progress=progress,
                                     cancelled=cancelled, n_tables=len(specs) + len(chosen)),
                   cache_dir)


def load_measured(
    pack_path: str | os.PathLike,
    names: Iterable[str] | None = None,
    cache_dir: str | os.PathLike | None = None,
    n_components: int = N_COMPONENTS,
    progress: Progress | None = None,
    cancelled: CancelCheck | None = None,
) -> Basis:
    """A basis from measured materials: the neural-BRDF pack's (``core.brdf.nbrdf``)
    materials ``names`` (default: all), tabulated on the MERL grid; cached under the
    pack's content hash and the names. progress, cancelled: as in :func:`build`."""
    return _pack_basis(pack_path, None if names is None else tuple(names), False, cache_dir,
                       n_components, progress, cancelled)


def load_union(
    pack_path: str | os.PathLike,
    names: Iterable[str] | None = None,
    cache_dir: str | os.PathLike | None = None,
    n_components: int = N_COMPONENTS,
    progress: Progress | None = None,
    cancelled: CancelCheck | None = None,
) -> Basis:
    """A basis from the built-in analytic database and the pack's measured materials
    ``names`` (default: all) together; cached like the two. progress, cancelled: as in
    :func:`build`."""
    return _pack_basis(pack_path, None if names is None else tuple(names), True, cache_dir,
                       n_components, progress, cancelled)
