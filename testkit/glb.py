"""Reading a glTF 2.0 binary (.glb) back, for the export's tests: Khronos' layout, a
12-byte header ("glTF", version 2, total length) then chunks of (length, type,
data), the first the JSON document, the second (optional) the binary buffer."""

from __future__ import annotations

import json
import pathlib
import struct


def read_glb(path: str | pathlib.Path) -> tuple[dict, bytes]:
    """(the JSON chunk as a dict, the BIN chunk's bytes, b"" without one). ValueError
    for a file whose header is not a glTF 2.0 binary of its own length."""
    data = pathlib.Path(path).read_bytes()
    magic, version, length = struct.unpack_from("<4sII", data, 0)
    if (magic, version, length) != (b"glTF", 2, len(data)):
        raise ValueError(f"{path} is not a glTF 2.0 binary ({magic!r}, version {version}, "
                         f"length {length} of {len(data)} bytes)")
    chunks, at = {}, 12
    while at < len(data):
        size, kind = struct.unpack_from("<I4s", data, at)
        chunks[kind] = data[at + 8:at + 8 + size]
        at += 8 + size
    return json.loads(chunks[b"JSON"]), chunks.get(b"BIN\x00", b"")
