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
import os
import pathlib


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
