"""Writing output files so that nothing is ever half-written.

Every file the extension writes (tables, pictures, reports, the saved scene)
goes through :func:`replacing`: the content is written to a temporary name in the
destination's own folder (so the final rename stays on one file system, and so
is atomic) and renamed into place only when it is complete. An error or an
interruption (Ctrl+C, Esc, a full disk) at any moment leaves the destination as
it was (absent, or the previous complete file) and removes the temporary file.
"""

from __future__ import annotations

import contextlib
import fnmatch
import os
import pathlib

OUTPUT_MARKER = ".brdf_reconstruct_output"
"""Left in an output folder by every run: the files of :data:`OUTPUT_NAMES` beside
it were written by a run, and the next run may replace them."""
OUTPUT_NAMES = ("brdf_*.binary", "brdf_*.png", "brdf_*.exr", "brdf_*.glb", "report.json",
                "scene.blend")
"""The names a run writes in its output folder (shell patterns)."""


def temporary_name(path: str | os.PathLike) -> pathlib.Path:
    """A hidden name beside ``path`` that keeps its suffix (writers such as
    OpenImageIO and Blender choose the format by the suffix), unique per process:
    ``dir/.name.<pid>.tmp.<suffix>``."""
    path = pathlib.Path(path)
    return path.with_name(f".{path.stem}.{os.getpid()}.tmp{path.suffix}")


@contextlib.contextmanager
def replacing(path: str | os.PathLike):
    """``with replacing(path) as tmp:`` write the whole file to ``tmp`` (a
    :class:`pathlib.Path`); on a clean exit it is renamed to ``path``
    (``os.replace``), on any exception (``KeyboardInterrupt`` included) it is
    removed and ``path`` is left untouched. The folder must exist."""
    path = pathlib.Path(path)
    tmp = temporary_name(path)
    try:
        yield tmp
        if not tmp.is_file():
            raise OSError(f"nothing was written for {path}")
        os.replace(tmp, path)
    except BaseException:
        with contextlib.suppress(OSError):
            tmp.unlink()
        raise


def write_bytes(path: str | os.PathLike, data: bytes) -> None:
    """Write ``data`` to ``path`` through :func:`replacing`."""
    with replacing(path) as tmp, open(tmp, "wb") as f:
        f.write(data)


def write_text(path: str | os.PathLike, text: str) -> None:
    """Write UTF-8 ``text`` to ``path`` through :func:`replacing`."""
    write_bytes(path, text.encode("utf-8"))


def files_a_run_would_replace(folder: str | os.PathLike) -> list[str]:
    """Sorted names in ``folder`` that a run would write over although no run wrote
    them: the :data:`OUTPUT_NAMES` present in a folder without
    :data:`OUTPUT_MARKER`. [] for a missing folder or one an earlier run wrote."""
    folder = pathlib.Path(folder)
    if not folder.is_dir() or (folder / OUTPUT_MARKER).is_file():
        return []
    return sorted(p.name for p in folder.iterdir()
                  if any(fnmatch.fnmatch(p.name, pattern) for pattern in OUTPUT_NAMES))


def mark_output_folder(folder: str | os.PathLike) -> None:
    """Leave :data:`OUTPUT_MARKER` in ``folder`` (the run's outputs are there)."""
    write_text(pathlib.Path(folder) / OUTPUT_MARKER,
               "written by BRDF Reconstruct; the next run may replace its outputs here\n")
