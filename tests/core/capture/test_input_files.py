"""core.capture.input_files: the job's .blend and mesh files checked by their bytes.

The good files are written here by the formats' specifications (PLY header and
binary rows, OBJ lines, binary and ASCII STL); that files Blender itself writes
pass is tested with Blender in tests/blender/test_job.py.
"""

import gzip

import numpy as np
import pytest

from brdf_reconstruct.core.capture import input_files

TRIANGLE = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0]], dtype="<f4")


def _ply_header(fmt: str, n_vertices: int, n_faces: int | None, face="face") -> bytes:
    lines = ["ply", f"format {fmt} 1.0", "comment written by the test",
             f"element vertex {n_vertices}", "property float x", "property float y",
             "property float z"]
    if n_faces is not None:
        lines += [f"element {face} {n_faces}", "property list uchar int vertex_indices"]
    return ("\n".join(lines + ["end_header"]) + "\n").encode()


def binary_ply(vertex=None, normal=None, order="<") -> bytes:
    """One triangle, binary (little-endian, or big with order ">"): 3 x 12 bytes of
    vertices (24 with normals: the last vertex's normal is ``normal``), then the face
    as a uchar count and three int32 indices. vertex: the last vertex's x, y, z."""
    points = TRIANGLE.astype(order + "f4")
    if vertex is not None:
        points[2] = vertex
    header = _ply_header("binary_little_endian" if order == "<" else "binary_big_endian",
                         3, 1)
    if normal is not None:
        normals = np.zeros((3, 3), order + "f4")
        normals[:, 2], normals[2] = 1.0, normal
        points = np.concatenate([points, normals], axis=1)
        header = header.replace(b"property float z\n", b"property float z\nproperty float nx"
                                b"\nproperty float ny\nproperty float nz\n")
    face = np.uint8(3).tobytes() + np.array([0, 1, 2], order + "i4").tobytes()
    return header + points.tobytes() + face


def ascii_ply(n_faces=1, face="face") -> bytes:
    body = "0 0 0\n1 0 0\n0 1 0\n" + "3 0 1 2\n" * n_faces
    return _ply_header("ascii", 3, n_faces, face) + body.encode()


def binary_stl(n: int = 1, vertex=None) -> bytes:
    rows = np.zeros(n, dtype=[("normal", "<f4", 3), ("v", "<f4", (3, 3)), ("attr", "<u2")])
    rows["normal"] = (0, 0, 1)
    rows["v"] = TRIANGLE
    if vertex is not None:  # the last triangle's last vertex
        rows["v"][-1, 2] = vertex
    return b"binary STL written by the test".ljust(80, b" ") + np.uint32(n).tobytes() \
        + rows.tobytes()


ASCII_STL = b"""solid test
facet normal 0 0 1
 outer loop
  vertex 0 0 0
  vertex 1 0 0
  vertex 0 1 0
 endloop
endfacet
endsolid test
"""
# a binary PLY cut after its vertices: the header and 3 x 12 bytes, 1 short of the
# bound (the face's count byte)
CUT = len(_ply_header("binary_little_endian", 3, 1)) + 36
OBJ = b"# a triangle\nv 0 0 0\nv 1 0 0\nv 0 1 0\nvn 0 0 1\nf 1//1 2//1 3//1\n"


def _write(tmp_path, name, data: bytes):
    path = tmp_path / name
    path.write_bytes(data)
    return path


@pytest.mark.parametrize("name, data", [
    ("binary.ply", binary_ply()),
    ("ascii.ply", ascii_ply()),
    ("crlf.ply", ascii_ply().replace(b"\n", b"\r\n")),
    ("strips.ply", ascii_ply(face="tristrips")),  # Blender makes faces of tristrips
    ("binary.stl", binary_stl(2)),
    ("ascii.stl", ASCII_STL),
    ("mesh.obj", OBJ),
    ("indented.obj", b"o Scan\n  v 0 0 0\n\tv 1 0 0\nv 0 1 0\n  f 1 2 3\n"),
    # finite numbers everywhere; words with "inf" or "nan" in them outside the vertices
    ("normals.ply", binary_ply(normal=(0, 0.6, 0.8))),
    ("big_endian.ply", binary_ply(order=">")),
    ("words.obj", b"# information: a banana\nmtllib infinite.mtl\n" + OBJ),
])
def test_good_mesh_files_pass(tmp_path, name, data):
    assert input_files.check_mesh(_write(tmp_path, name, data)) is None


@pytest.mark.parametrize("name, data, message", [
    ("empty.ply", b"", "mesh empty.ply is empty (0 bytes): export the scan again"),
    ("empty.obj", b"", "mesh empty.obj is empty (0 bytes)"),
    ("empty.stl", b"", "mesh empty.stl is empty (0 bytes)"),
    ("text.ply", b"these are my notes\n", 'mesh text.ply is not a PLY file (it does not '
                                          'start with "ply")'),
    ("obj.ply", OBJ, "mesh obj.ply is not a PLY file"),
    ("no_end.ply", _ply_header("ascii", 3, 1)[:-len(b"end_header\n")],
     "mesh no_end.ply is not a complete PLY file (no end_header line)"),
    ("format.ply", ascii_ply().replace(b"format ascii", b"format utf8"),
     "mesh format.ply is not a valid PLY file (unknown format utf8)"),
    ("type.ply", ascii_ply().replace(b"property float y", b"property quad y"),
     "unknown property type quad"),
    ("points.ply", _ply_header("ascii", 3, None) + b"0 0 0\n1 0 0\n0 1 0\n",
     "mesh points.ply has no faces"),
    ("zero.ply", ascii_ply(n_faces=0), "mesh zero.ply has no faces"),
    # the face rows missing: fewer bytes than the header's elements need
    ("cut.ply", binary_ply()[:CUT],
     f"mesh cut.ply is truncated ({CUT} bytes, its header needs at least {CUT + 1})"),
    ("points.obj", b"v 0 0 0\nv 1 0 0\nv 0 1 0\n", "mesh points.obj has no faces"),
    ("text.obj", b"hello, this is not a mesh\n", "mesh text.obj is not an OBJ file"),
    ("binary.obj", bytes(range(256)) * 4, "mesh binary.obj is not an OBJ file"),
    ("zero.stl", binary_stl(0), "mesh zero.stl has no faces"),
    ("solid.stl", b"solid nothing\nendsolid nothing\n", "mesh solid.stl has no faces"),
    ("text.stl", b"hello, this is not a mesh\n", "mesh text.stl is not an STL file"),
    ("cut.stl", binary_stl(2)[:-10], "mesh cut.stl is not an STL file"),
    # a NaN or Inf vertex: Blender's PLY importer reads it as 0, a spike to the origin
    ("nan.ply", binary_ply(vertex=(1, 2, np.nan)), "mesh nan.ply has vertices with NaN or Inf"),
    ("inf_be.ply", binary_ply(vertex=(np.inf, 0, 0), order=">"), "has vertices with NaN or Inf"),
    ("nan_normal.ply", binary_ply(normal=(0, np.nan, 1)), "has vertices with NaN or Inf"),
    ("inf.ply", ascii_ply().replace(b"1 0 0\n", b"1 -inf 0\n"), "has vertices with NaN or Inf"),
    ("nan.ply", ascii_ply().replace(b"1 0 0\n", b"1 NaN 0\n"), "has vertices with NaN or Inf"),
    ("nan.obj", OBJ.replace(b"v 1 0 0", b"v 1 nan 0"), "mesh nan.obj has vertices with NaN"),
    ("nan.stl", binary_stl(2, vertex=(0, np.nan, 0)), "mesh nan.stl has vertices with NaN"),
    ("inf.stl", ASCII_STL.replace(b"vertex 1 0 0", b"vertex 1 inf 0"), "has vertices with NaN"),
])
def test_bad_mesh_files_are_one_sentence(tmp_path, name, data, message):
    path = _write(tmp_path, name, data)
    with pytest.raises(ValueError) as error:
        input_files.check_mesh(path)
    text = str(error.value)
    assert message in text and "\n" not in text, text
    assert path.read_bytes() == data  # never changed


def test_a_binary_ply_at_the_size_bound_passes(tmp_path):
    """The bound is the header plus every row's fixed bytes, a list counted by its
    count byte only (it may be empty): CUT + 1 bytes passes, as the whole file."""
    input_files.check_mesh(_write(tmp_path, "whole.ply", binary_ply()))
    input_files.check_mesh(_write(tmp_path, "bound.ply", binary_ply()[:CUT + 1]))


def test_the_field_is_named(tmp_path):
    path = _write(tmp_path, "x.ply", b"")
    with pytest.raises(ValueError, match="^scan x.ply is empty"):
        input_files.check_mesh(path, field="scan")


def test_a_folder_or_another_suffix_is_refused(tmp_path):
    (tmp_path / "scan.ply").mkdir()
    with pytest.raises(ValueError, match="is not a file"):
        input_files.check_mesh(tmp_path / "scan.ply")
    with pytest.raises(ValueError, match="mesh must be .ply, .obj or .stl, got scan.fbx"):
        input_files.check_mesh(_write(tmp_path, "scan.fbx", OBJ))


@pytest.mark.parametrize("name, data", [
    ("plain.blend", b"BLENDER17-01v0500" + bytes(64)),
    ("old.blend", b"BLENDER-v279REND" + bytes(64)),
    ("zstd.blend", b"\x28\xb5\x2f\xfd" + bytes(64)),  # Blender 3.0+ compression
    ("gzip.blend", gzip.compress(b"BLENDER-v279" + bytes(64), mtime=0)),  # before 3.0
])
def test_good_blend_headers_pass(tmp_path, name, data):
    assert input_files.check_blend(_write(tmp_path, name, data)) is None


@pytest.mark.parametrize("name, data, message", [
    ("empty.blend", b"", "blend empty.blend is empty (0 bytes): save the scene again"),
    ("text.blend", b"scene notes, not a scene\n", "blend text.blend is not a Blender file"),
    ("short.blend", b"BLEND", "blend short.blend is not a Blender file"),
    ("ply.blend", ascii_ply(), "blend ply.blend is not a Blender file"),
])
def test_bad_blend_files_are_one_sentence(tmp_path, name, data, message):
    path = _write(tmp_path, name, data)
    with pytest.raises(ValueError) as error:
        input_files.check_blend(path)
    text = str(error.value)
    assert message in text and "\n" not in text, text
    assert "point blend at a .blend saved by Blender" in text or "empty" in text
