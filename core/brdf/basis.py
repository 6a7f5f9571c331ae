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

import collections
import dataclasses
import functools
import hashlib
import json
import os
import pathlib
import tempfile
import time
from collections.abc import Callable, Iterable, Sequence
from concurrent.futures import ThreadPoolExecutor

import numpy as np

from ..progress import CancelCheck, Progress, check, report
from . import merl

EPS = 1e-3  # Nielsen's eps in the log-relative mapping
COSINE_CLIP = 0.01  # lower clip of the cosine map
N_COMPONENTS = 40  # components kept by default: 1.1 M cells x 40 x 4 B = 175 MB cached
FORMAT_VERSION = 4  # bump when the cache layout or the mapping changes (3: float32 mapping,
# info["materials"]; 4: x_range of the mapped data again, not of the centred data)
_BLOCK_BYTES = 1 << 26  # a float64 copy of a block of cells while building: 64 MB


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
        c, m_eps = _mapping_f64(self)
        shape = (-1,) + (1,) * (np.ndim(rho) - 1)
        rho = np.maximum(rho, 0.0)
        return np.log((rho * c[rows].reshape(shape) + EPS) / m_eps[rows].reshape(shape))

    def from_mapped(self, x: np.ndarray, rows: np.ndarray | slice = slice(None)) -> np.ndarray:
        """Inverse mapping: x (N, ...) at basis rows -> rho (N, ...) in 1/sr, >= 0, finite."""
        c, m_eps = _mapping_f64(self)
        c, m_eps = c[rows], m_eps[rows]
        shape = (-1,) + (1,) * (np.ndim(x) - 1)
        lo, hi = self.x_range
        margin = 5.0  # allow extrapolation by e^5 beyond anything seen in training
        # (exp(x) (m + EPS) - EPS) / c, in place on one float64 copy of x
        rho = np.clip(np.asarray(x, dtype=np.float64), lo - margin, hi + margin)
        np.exp(rho, out=rho)
        rho *= m_eps.reshape(shape)
        rho -= EPS
        rho /= c.reshape(shape)
        return np.maximum(rho, 0.0, out=rho)

    def source_rows(self, linear: np.ndarray) -> np.ndarray:
        """Basis row each flat cell index (N,) takes its value from in
        :meth:`table_from_rows` (its own row inside the basis) -> (N,) int64."""
        return _fill_source(self)[np.asarray(linear, dtype=np.int64)]

    def table_from_rows(self, values: np.ndarray) -> np.ndarray:
        """Per-row RGB values (R, 3) as a full table (3, 90, 90, 180): cells outside the
        basis take the value of the basis cell ``merl.fill_unmeasured`` would copy."""
        source = _fill_source(self)
        out = np.empty((3, merl.N_CELLS), dtype=np.result_type(values))
        for c in range(3):  # a gather per channel into the C-ordered table (no copies)
            np.take(values[:, c], source, out=out[c])
        return out.reshape(3, *merl.SHAPE)

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


def _mapping_f64(basis: Basis) -> tuple[np.ndarray, np.ndarray]:
    """(R,) float64 cosine weight and median + EPS of every basis row, kept after
    first use (the inverse mapping of a full table needs them every time)."""
    cached = basis._derived.get("mapping")
    if cached is None:
        cached = (basis.cosine.astype(np.float64), basis.median.astype(np.float64) + EPS)
        basis._derived["mapping"] = cached
    return cached


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


def _workers(workers: int | None) -> int:
    return max(1, int(workers) if workers is not None else min(2, os.cpu_count() or 1))


def _ordered(pool: ThreadPoolExecutor, fn, items, window: int):
    """``fn(item)`` for each item in ``pool``, yielded in order, at most ``window``
    running or waiting at once (bounds the memory of results not yet consumed). On
    an exception in the consumer or in ``fn``, the waiting calls are dropped."""
    pending: collections.deque = collections.deque()
    try:
        for item in items:
            pending.append(pool.submit(fn, item))
            if len(pending) >= window:
                yield pending.popleft().result()
        while pending:
            yield pending.popleft().result()
    finally:
        for future in pending:
            future.cancel()


class _Columns:
    """The training data being gathered: one float32 row per channel, cosine-weighted
    rho at the valid cells ``geo``; ``keep`` marks the cells every table measured."""

    def __init__(self, n_tables: int | None):
        self.geo = np.flatnonzero(merl.valid_cells())
        self.cos = cosine_map()[self.geo].astype(np.float32)
        self.keep = np.ones(len(self.geo), dtype=bool)
        # filled in place when the number of tables is known (no second copy), else
        # gathered and joined at the end
        self.X = np.empty((3 * n_tables, len(self.geo)), np.float32) if n_tables else None
        self.parts: list[np.ndarray] = []
        self.n_done = 0

    def values(self, i: int, table: np.ndarray) -> np.ndarray:
        """Training table i, (3, 90, 90, 180) or (3, n_valid), as (3, n_valid)."""
        table = np.asarray(table)
        if table.shape == (3, len(self.geo)):
            return table
        if table.shape != (3, *merl.SHAPE):
            raise ValueError(f"training table {i} has shape {table.shape}, not (3, 90, 90, 180)")
        return table.reshape(3, -1)[:, self.geo]

    def put(self, i: int, rho: np.ndarray) -> None:
        if self.X is not None and i >= len(self.X) // 3:
            raise ValueError(f"more training tables than the {len(self.X) // 3} announced")
        self.keep &= np.all(np.isfinite(rho) & (rho >= 0), axis=0)
        if self.X is not None:
            np.multiply(rho, self.cos, out=self.X[3 * i : 3 * i + 3], casting="same_kind")
        else:
            self.parts.append((rho * self.cos).astype(np.float32))
        self.n_done = i + 1

    def matrix(self) -> np.ndarray:
        if self.n_done == 0:
            raise ValueError("no training tables given")
        X = self.X[: 3 * self.n_done] if self.X is not None else np.concatenate(self.parts)
        self.X, self.parts = None, []
        return X


def build(
    tables: Iterable[np.ndarray],
    n_components: int = N_COMPONENTS,
    fingerprint: str = "",
    progress: Progress | None = None,
    cancelled: CancelCheck | None = None,
    n_tables: int | None = None,
    workers: int | None = None,
    names: Sequence[str] | None = None,
) -> Basis:
    """Build a basis from a stream of tables, read one after the other.

    tables: iterable of (3, 90, 90, 180) arrays in 1/sr (NaN = unmeasured), or of
    (3, n_valid) arrays at the cells ``merl.valid_cells()`` marks (in that order);
    each contributes three columns. Only cells above the horizon at their centre and
    measured in every table are kept. n_components: k, capped by the number of
    columns. progress: optional ``progress(fraction, message)`` (``core.progress``),
    called after every table and every block of cells, so at least once a second on
    the built-in database; n_tables: the stream's length, for its fractions.
    cancelled: optional callable checked as often; True raises
    ``core.progress.Cancelled`` (nothing is kept). workers: threads for the
    decomposition (default: up to 2, the cores). names: as in :func:`build_from`.
    Memory: one float32 value per (column, cell), 0.44 GB per 100 channels, and
    about 64 MB per worker.
    """
    t0 = time.perf_counter()
    stage = _stage(progress, cancelled)
    cols = _Columns(n_tables)
    of = f"/{n_tables}" if n_tables else ""
    for i, table in enumerate(tables):
        cols.put(i, cols.values(i, table))
        stage(0.8 * (cols.n_done / n_tables) if n_tables else 0.0,
              f"building the BRDF basis (once): table {cols.n_done}{of}")
    if names is not None and len(names) != cols.n_done:
        raise ValueError(f"{len(names)} names for {cols.n_done} training tables")
    return _named(_decompose(cols, n_components, fingerprint, stage, _workers(workers), t0),
                  names)


def build_from(
    makers: Sequence[Callable[[], np.ndarray]],
    n_components: int = N_COMPONENTS,
    fingerprint: str = "",
    progress: Progress | None = None,
    cancelled: CancelCheck | None = None,
    workers: int | None = None,
    names: Sequence[str] | None = None,
) -> Basis:
    """Build a basis from training tables made on demand, ``workers`` at once.

    makers: one zero-argument callable per training material, returning its table
    as :func:`build` takes it (numpy releases the GIL in its loops, so threads make
    tables side by side). The basis is the same as ``build`` of the same tables, in
    the same order. progress, cancelled: as in :func:`build`; a cancel waits for the
    tables being made (a fraction of a second each). names: the materials' names,
    one per maker, kept in ``info["materials"]`` so that a material is never scored
    by a basis built from it.
    """
    if names is not None and len(names) != len(makers):
        raise ValueError(f"{len(names)} names for {len(makers)} training tables")
    t0 = time.perf_counter()
    stage = _stage(progress, cancelled)
    n = len(makers)
    cols = _Columns(n)
    w = _workers(workers)
    with ThreadPoolExecutor(w) as pool:
        made = _ordered(pool, lambda i: cols.values(i, makers[i]()), range(n), w + 1)
        for i, rho in enumerate(made):
            cols.put(i, rho)
            stage(0.8 * (i + 1) / n, f"building the BRDF basis (once): table {i + 1}/{n}")
    return _named(_decompose(cols, n_components, fingerprint, stage, w, t0), names)


def _named(B: Basis, names) -> Basis:
    """``B`` with its training materials' names in ``info["materials"]`` (if given)."""
    if names is not None:
        B.info["materials"] = [str(x) for x in names]
    return B


def _stage(progress, cancelled):
    def stage(fraction: float, message: str) -> None:
        check(cancelled)
        report(progress, fraction, message)

    return stage


def _map_block(X: np.ndarray, r) -> tuple:
    """Pass 1 on the cells ``r`` (a slice or an index array into X's columns):
    median over the columns, log-relative mapping, mean, centring, written back in
    place into X; returns (median, mean, min, max, Gram of the centred block)."""
    x = X[:, r]  # float32, a copy for an index array, a view for a slice
    # the median in float64 along contiguous rows (twice as fast as along the strided
    # axis), on a copy it may reorder
    m = np.median(x.T.astype(np.float64, order="C"), axis=1, overwrite_input=True)
    x = np.array(x, dtype=np.float32, copy=True)
    x += np.float32(EPS)
    x /= (m + EPS).astype(np.float32)
    np.log(x, out=x)
    lo, hi = float(x.min()), float(x.max())  # of the mapped data, before centring
    mu = x.mean(axis=0, dtype=np.float64)
    x -= mu.astype(np.float32)
    gram = (x @ x.T).astype(np.float64)
    X[:, r] = x
    return m, mu, lo, hi, gram


def _decompose(cols: _Columns, n_components, fingerprint, stage, workers, t0) -> Basis:
    """The mapping and the principal components of the gathered columns (Gram matrix
    of the centred data, a few hundred columns square: ``D^T D = V S^2 V^T``, so
    ``Q = U S = D V``)."""
    X = cols.matrix()
    n_cols = X.shape[0]
    rows = np.flatnonzero(cols.keep)
    if len(rows) < n_cols:
        raise ValueError(f"only {len(rows)} cells are measured in every training table")
    contiguous = len(rows) == rows[-1] - rows[0] + 1
    block = int(np.clip(_BLOCK_BYTES // (8 * n_cols), 4096, 1 << 16)) // 1024 * 1024
    starts = range(0, len(rows), block)
    n_blocks = len(starts)

    def cells(start: int):
        stop = min(start + block, len(rows))
        return slice(rows[start], rows[stop - 1] + 1) if contiguous else rows[start:stop]

    median = np.empty(len(rows), dtype=np.float32)
    mean = np.empty(len(rows), dtype=np.float32)
    gram = np.zeros((n_cols, n_cols))
    x_lo, x_hi = np.inf, -np.inf
    with ThreadPoolExecutor(workers) as pool:
        done = _ordered(pool, lambda s: _map_block(X, cells(s)), starts, workers + 1)
        for b, (start, (m, mu, lo, hi, g)) in enumerate(zip(starts, done, strict=True)):
            stop = min(start + block, len(rows))
            median[start:stop], mean[start:stop] = m, mu
            x_lo, x_hi = min(x_lo, lo), max(x_hi, hi)
            gram += g  # in block order: the same sum whatever the threads did
            stage(0.8 + 0.15 * (b + 1) / n_blocks, "building the BRDF basis (once): "
                  f"principal components, block {b + 1}/{n_blocks}")
    eigval, V = np.linalg.eigh(gram)
    order = np.argsort(eigval)[::-1]
    eigval = np.clip(eigval[order], 0.0, None)
    V = V[:, order]
    k = int(min(n_components, n_cols))
    Vk = np.ascontiguousarray(V[:, :k], dtype=np.float32)
    Q = np.empty((len(rows), k), dtype=np.float32)
    for b, start in enumerate(starts):
        stop = min(start + block, len(rows))
        Q[start:stop] = X[:, cells(start)].T @ Vk
        stage(0.95 + 0.05 * (b + 1) / n_blocks, "building the BRDF basis (once): "
              f"basis vectors, block {b + 1}/{n_blocks}")
    total = float(eigval.sum())
    info = {
        "n_columns": int(n_cols),
        "n_cells": int(len(rows)),
        "n_components": k,
        "explained_variance": float(eigval[:k].sum() / total) if total > 0 else 1.0,
        "build_seconds": time.perf_counter() - t0,
    }
    return Basis(
        cells=cols.geo[rows].astype(np.int64),
        Q=Q,
        mean=mean,
        median=median,
        cosine=cols.cos[rows],
        singular_values=np.sqrt(eigval[:k]),
        x_range=np.array([x_lo, x_hi]),
        fingerprint=fingerprint,
        info=info,
    )


# ------------------------------------------------------------------------------- cache
def default_cache_dir() -> pathlib.Path:
    """``$BRDF_RECONSTRUCT_CACHE`` (a relative path is taken from the working folder
    now, made absolute) or ``~/.cache/brdf_reconstruct``. Blender passes its extension
    user directory instead."""
    env = os.environ.get("BRDF_RECONSTRUCT_CACHE")
    if env:
        return pathlib.Path(os.path.abspath(os.path.expanduser(env)))
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
    makers = [functools.partial(database.valid_values, s) for s in specs]
    return _cached(fp, lambda: build_from(makers, n_components, fp, progress=progress,
                                          cancelled=cancelled,
                                          names=[s["name"] for s in specs]), cache_dir)


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
                      cancelled=cancelled, n_tables=len(files), names=[f.stem for f in files]),
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

    pack_path = nbrdf.BUNDLED_PACK if pack_path is None else pack_path
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

    makers = [functools.partial(database.valid_values, s) for s in specs]
    makers += [functools.partial(nbrdf.valid_values, pack, pack.index(n)) for n in chosen]
    names = [s["name"] for s in specs] + list(chosen)
    return _cached(fp, lambda: build_from(makers, n_components, fp, progress=progress,
                                          cancelled=cancelled, names=names), cache_dir)


def load_measured(
    pack_path: str | os.PathLike | None = None,
    names: Iterable[str] | None = None,
    cache_dir: str | os.PathLike | None = None,
    n_components: int = N_COMPONENTS,
    progress: Progress | None = None,
    cancelled: CancelCheck | None = None,
) -> Basis:
    """A basis from measured materials: the neural-BRDF pack's (``core.brdf.nbrdf``;
    default: the bundled ``nbrdf.BUNDLED_PACK``) materials ``names`` (default: all),
    tabulated on the MERL grid, two at a time; cached under the pack's content hash
    and the names. progress, cancelled: as in :func:`build`."""
    return _pack_basis(pack_path, None if names is None else tuple(names), False, cache_dir,
                       n_components, progress, cancelled)


def load_union(
    pack_path: str | os.PathLike | None = None,
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
