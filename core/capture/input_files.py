"""Header checks of the files a job names, before any work: the scene (``.blend``)
and the scan (``.ply``, ``.obj``, ``.stl``).

Pure Python on the files' bytes (no bpy): a file that Blender would refuse with
a traceback, or import as nothing, is refused here with one sentence naming the
job's field and the file and saying what to do (ValueError). The checks read
the header (the first bytes, a PLY's header lines) and, for OBJ and ASCII STL,
search the file for a face record without reading it into Python objects
(``mmap``). They never change the file.

What each check accepts:

- ``.blend``: Blender's header ``BLENDER``, or a zstd (Blender 3.0+) or gzip
  (older) compressed file.
- ``.ply``: ``ply`` on the first line, a known ``format``, an ``end_header``
  line, at least one face (``element face N`` or ``element tristrips N``, N > 0);
  for the binary formats, at least as many bytes as the header's elements need
  (every list taken as empty: a lower bound), else the file is truncated.
- ``.obj``: at least one vertex line (``v x y z``) and one face line (``f ...``).
- ``.stl``: binary (84 bytes of header and count, then 50 bytes per triangle,
  the count > 0) or ASCII (``solid`` first, at least one ``facet``).

Every format: no vertex coordinate or normal that is NaN or Inf (Blender's PLY,
OBJ and STL importers read such a number as 0: a spike to the origin no photo
can show). Binary PLY vertices (when no list comes before them) and binary STL
triangles are read as numpy rows from the mapped file; ASCII files are searched
for a ``nan`` or ``inf`` word in their vertex data.
"""

from __future__ import annotations

import mmap
import pathlib
import re

import numpy as np

BLEND_MAGICS = (b"BLENDER", b"\x28\xb5\x2f\xfd", b"\x1f\x8b")  # plain, zstd, gzip
PLY_FORMATS = ("ascii", "binary_little_endian", "binary_big_endian")
PLY_FACE_ELEMENTS = ("face", "tristrips")  # both become faces in Blender's importer
# bytes of each PLY scalar type (both spellings of the standard)
PLY_SIZES = {"char": 1, "uchar": 1, "int8": 1, "uint8": 1, "short": 2, "ushort": 2,
             "int16": 2, "uint16": 2, "int": 4, "uint": 4, "int32": 4, "uint32": 4,
             "float": 4, "float32": 4, "double": 8, "float64": 8}
# numpy codes of the PLY scalar types
PLY_NUMPY = {"char": "i1", "uchar": "u1", "int8": "i1", "uint8": "u1", "short": "i2",
             "ushort": "u2", "int16": "i2", "uint16": "u2", "int": "i4", "uint": "u4",
             "int32": "i4", "uint32": "u4", "float": "f4", "float32": "f4",
             "double": "f8", "float64": "f8"}
PLY_CHECKED = ("x", "y", "z", "nx", "ny", "nz")  # vertex properties that must be finite
# a "nan" or "inf" word (any case, any sign) in an ASCII file's numbers
NONFINITE_WORD = rb"(?<![A-Za-z_])[-+]?(?:nan|inf)"
PLY_HEADER_MAX = 1 << 16  # a PLY header longer than 64 KiB is taken as no header
STL_HEADER = 84  # 80 bytes of header, a uint32 triangle count
STL_TRIANGLE = 50  # normal, three vertices (12 float32) and a uint16


def check_blend(path: str | pathlib.Path, field: str = "blend") -> None:
    """ValueError (one sentence) unless ``path`` starts as a .blend file does."""
    path, head = _head(path, field, len(BLEND_MAGICS[0]), "save the scene again")
    if not head.startswith(BLEND_MAGICS):
        raise ValueError(f"{field} {path.name} is not a Blender file (it does not start "
                         "with BLENDER and is not zstd- or gzip-compressed): point "
                         f"{field} at a .blend saved by Blender")


def check_mesh(path: str | pathlib.Path, field: str = "mesh") -> None:
    """ValueError (one sentence) unless ``path`` (.ply, .obj or .stl, by its suffix)
    looks like a mesh file of that format holding at least one face."""
    path = pathlib.Path(path)
    kind = path.suffix.lower()
    checks = {".ply": _check_ply, ".obj": _check_obj, ".stl": _check_stl}
    if kind not in checks:
        raise ValueError(f"{field} must be .ply, .obj or .stl, got {path.name}")
    path, _ = _head(path, field, 0, "export the scan again")
    try:
        checks[kind](path, field)
    except OSError as error:
        raise ValueError(f"{field} {path.name} cannot be read ({error.strerror}): check "
                         "that it is a readable file") from None


def _head(path, field: str, size: int, remedy: str) -> tuple[pathlib.Path, bytes]:
    """(path, its first ``size`` bytes); ValueError for a folder, an unreadable or
    an empty file."""
    path = pathlib.Path(path)
    if not path.is_file():
        raise ValueError(f"{field} {path} is not a file (a folder?): point {field} at a file")
    try:
        if path.stat().st_size == 0:
            raise ValueError(f"{field} {path.name} is empty (0 bytes): {remedy}")
        with open(path, "rb") as f:
            return path, f.read(size)
    except OSError as error:
        raise ValueError(f"{field} {path.name} cannot be read ({error.strerror}): check "
                         "that it is a readable file") from None


def _no_faces(field: str, path: pathlib.Path) -> ValueError:
    return ValueError(f"{field} {path.name} has no faces (a point cloud or an empty mesh): "
                      "give the scan as a mesh with faces")


def _nonfinite(field: str, path: pathlib.Path) -> ValueError:
    return ValueError(f"{field} {path.name} has vertices with NaN or Inf coordinates or "
                      "normals (Blender would import them as zeros): fix or delete them, "
                      "or export the scan again")


def _check_ply(path: pathlib.Path, field: str) -> None:
    with open(path, "rb") as f:
        head = f.read(PLY_HEADER_MAX)
    if re.match(rb"ply\r?\n", head) is None:
        raise ValueError(f'{field} {path.name} is not a PLY file (it does not start with '
                         '"ply"): export the scan again as PLY')
    end = re.search(rb"^end_header[ \t]*\r?\n", head, re.MULTILINE)
    if end is None:
        raise ValueError(f"{field} {path.name} is not a complete PLY file (no end_header "
                         "line): export the scan again")
    header = head[:end.start()].decode("ascii", errors="replace").splitlines()[1:]
    fmt, elements = None, []  # elements: [name, count, bytes per row at least, props]
    for words in (line.split() for line in header):
        if not words or words[0] in ("comment", "obj_info"):
            continue
        if words[0] == "format" and len(words) >= 2:
            fmt = words[1]
        elif words[0] == "element" and len(words) == 3 and words[2].isdigit():
            elements.append([words[1], int(words[2]), 0, []])
        elif words[0] == "property" and elements and len(words) >= 3:
            scalar = words[2] if words[1] == "list" else words[1]  # a list: its count
            if scalar not in PLY_SIZES:
                raise _bad_ply(path, field, f"unknown property type {scalar}")
            elements[-1][2] += PLY_SIZES[scalar]
            # (name, numpy code), the name None for a list (rows of varying size)
            elements[-1][3].append((words[-1] if words[1] != "list" else None,
                                    PLY_NUMPY[scalar]))
        else:
            raise _bad_ply(path, field, f"unreadable header line {' '.join(words)!r}")
    if fmt not in PLY_FORMATS:
        raise _bad_ply(path, field, f"unknown format {fmt}")
    if sum(count for name, count, _, _ in elements if name in PLY_FACE_ELEMENTS) == 0:
        raise _no_faces(field, path)
    if fmt != "ascii":
        need = end.end() + sum(count * row for _, count, row, _ in elements)
        size = path.stat().st_size
        if size < need:
            raise ValueError(f"{field} {path.name} is truncated ({size} bytes, its header "
                             f"needs at least {need}): export the scan again")
    _check_ply_vertices(path, field, fmt, end.end(), elements)


def _check_ply_vertices(path: pathlib.Path, field: str, fmt: str, start: int,
                        elements: list) -> None:
    """ValueError if a PLY vertex's position or normal (PLY_CHECKED) is NaN or Inf.
    Binary: the vertex rows read as numpy records (when only fixed-size rows come
    before them; a list before the vertices is not followed). ASCII: a nan or inf
    word anywhere after the header (the faces' indices are integers, so such a word
    is a vertex property)."""
    with open(path, "rb") as f, mmap.mmap(f.fileno(), 0, access=mmap.ACCESS_READ) as data:
        if fmt == "ascii":
            if re.compile(NONFINITE_WORD, re.IGNORECASE).search(data, start) is not None:
                raise _nonfinite(field, path)
            return
        order = "<" if fmt == "binary_little_endian" else ">"
        offset = start
        for name, count, row, props in elements:
            if any(p is None for p, _ in props):  # a list: rows of varying size
                return
            if name == "vertex":
                rows = np.frombuffer(data, count=count, offset=offset, dtype=np.dtype(
                    [(f"p{i}", order + code) for i, (_, code) in enumerate(props)]))
                axes = [f"p{i}" for i, (p, _) in enumerate(props) if p in PLY_CHECKED]
                bad = sum(int(np.count_nonzero(~np.isfinite(rows[a]))) for a in axes)
                del rows  # no view may outlive the mapping
                if bad:
                    raise _nonfinite(field, path)
                return
            offset += count * row


def _bad_ply(path: pathlib.Path, field: str, what: str) -> ValueError:
    return ValueError(f"{field} {path.name} is not a valid PLY file ({what}): export the "
                      "scan again")


def _check_obj(path: pathlib.Path, field: str) -> None:
    with open(path, "rb") as f, mmap.mmap(f.fileno(), 0, access=mmap.ACCESS_READ) as data:
        if re.search(rb"^[ \t]*v[ \t]", data, re.MULTILINE) is None:
            raise ValueError(f"{field} {path.name} is not an OBJ file (it has no vertex "
                             "lines): export the scan again as OBJ")
        if re.search(rb"^[ \t]*f[ \t]", data, re.MULTILINE) is None:
            raise _no_faces(field, path)
        if re.search(rb"^[ \t]*v[ \t][^\n]*" + NONFINITE_WORD, data,
                     re.MULTILINE | re.IGNORECASE) is not None:
            raise _nonfinite(field, path)


def _check_stl(path: pathlib.Path, field: str) -> None:
    size = path.stat().st_size
    with open(path, "rb") as f, mmap.mmap(f.fileno(), 0, access=mmap.ACCESS_READ) as data:
        if size >= STL_HEADER:
            count = int.from_bytes(data[80:STL_HEADER], "little")
            if size == STL_HEADER + STL_TRIANGLE * count:  # binary, as Blender decides
                if count == 0:
                    raise _no_faces(field, path)
                rows = np.frombuffer(data, count=count, offset=STL_HEADER, dtype=np.dtype(
                    [("normal", "<f4", 3), ("v", "<f4", (3, 3)), ("attr", "<u2")]))
                finite = bool(np.all(np.isfinite(rows["v"])))
                del rows  # no view may outlive the mapping
                if not finite:
                    raise _nonfinite(field, path)
                return
        if re.match(rb"\s*solid", data) is None:
            raise ValueError(f"{field} {path.name} is not an STL file (neither binary STL "
                             "of the size its triangle count gives nor ASCII starting with "
                             "solid): export the scan again as STL")
        if data.find(b"facet") < 0:
            raise _no_faces(field, path)
        if re.search(rb"vertex[^\n]*" + NONFINITE_WORD, data, re.IGNORECASE) is not None:
            raise _nonfinite(field, path)
