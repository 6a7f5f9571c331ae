"""A UV map made on a copy of a scan that has none (issue 16): the copy is mapped,
the user's object and mesh are not touched, and the panel's operator and a job's
``uv_on_copy`` both make the copy the run's scan."""

import hashlib

import numpy as np
import pytest

bpy = pytest.importorskip("bpy")

from brdf_reconstruct.brdf_addon import job as job_file  # noqa: E402
from brdf_reconstruct.brdf_addon import uv_copy  # noqa: E402
from testkit import blender_scene as BS  # noqa: E402


def _digest(mesh) -> str:
    """The mesh's geometry, faces, attributes and UV maps, hashed."""
    co = np.empty(len(mesh.vertices) * 3, dtype=np.float32)
    mesh.vertices.foreach_get("co", co)
    loops = np.empty(len(mesh.loops), dtype=np.int32)
    mesh.loops.foreach_get("vertex_index", loops)
    h = hashlib.sha256(co.tobytes() + loops.tobytes())
    h.update(repr(sorted((a.name, a.domain, a.data_type) for a in mesh.attributes)).encode())
    h.update(repr([layer.name for layer in mesh.uv_layers]).encode())
    return h.hexdigest()


@pytest.fixture
def bare(tmp_path, registered):
    """The tiny scene, its scan's UV map removed (a scan delivered without UVs)."""
    built = BS.build(tmp_path, photo=False)
    layers = built["scan"].data.uv_layers
    while len(layers):
        layers.remove(layers[0])
    built["scene"].brdf.target = built["scan"]
    return built


def test_the_copy_gets_a_uv_map_and_the_scan_is_unchanged(bare):
    scan = bare["scan"]
    before = _digest(scan.data)
    names = {o.name for o in bpy.data.objects}
    bpy.context.view_layer.objects.active = bare["camera"]
    assert bpy.ops.brdf.uv_copy() == {"FINISHED"}
    s = bare["scene"].brdf
    copy = s.target
    assert copy.name == "Scan (UV)" and {o.name for o in bpy.data.objects} - names == {
        copy.name}
    assert copy.data is not scan.data and s.uv_map == uv_copy.UV_NAME
    uv = np.empty(len(copy.data.loops) * 2)
    copy.data.uv_layers[uv_copy.UV_NAME].data.foreach_get("uv", uv)
    uv = uv.reshape(-1, 2)
    assert np.isfinite(uv).all() and uv.min() >= -1e-6 and uv.max() <= 1.0 + 1e-6  # float32
    # every face unwrapped: each triangle has UV area (the islands fill part of [0, 1]^2)
    tri = uv.reshape(-1, 3, 2)
    area = 0.5 * np.abs(np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0]))
    assert (area > 0).all() and 0.3 < area.sum() <= 1.0
    assert (copy.matrix_world == scan.matrix_world) and list(copy.users_collection) == list(
        scan.users_collection)
    assert copy.material_slots[0].material == scan.material_slots[0].material
    # the user's object, mesh and UI state: as they were
    assert _digest(scan.data) == before and len(scan.data.uv_layers) == 0
    assert bpy.context.view_layer.objects.active == bare["camera"]
    assert bpy.context.object.mode == "OBJECT"
    # now the panel offers nothing more to do
    assert not bpy.ops.brdf.uv_copy.poll()


def test_a_scan_with_a_uv_map_needs_no_copy(bare):
    bare["scan"].data.uv_layers.new(name="UVMap")
    assert not bpy.ops.brdf.uv_copy.poll()
    with pytest.raises(ValueError, match=r"already has a UV map \('UVMap'\); no copy is needed"):
        uv_copy.make_uv_copy(bare["scene"], bare["scan"])


def test_a_job_with_uv_on_copy_runs_on_a_mapped_copy(bare, tmp_path):
    scene = bare["scene"]
    bpy.data.objects.remove(bare["camera"])  # a job without photos names no camera
    before = _digest(bare["scan"].data)
    job = job_file.Job(path=tmp_path / "job.toml", out=tmp_path / "out", object="Scan",
                       uv_on_copy=True, settings={"texture": True})
    job_file.apply(job, scene)
    assert scene.brdf.target.name == "Scan (UV)" and scene.brdf.texture
    assert uv_copy.UV_NAME in scene.brdf.target.data.uv_layers
    assert _digest(bare["scan"].data) == before
    (tmp_path / "job.toml").write_text('object = "Scan"\nuv_on_copy = "yes"\n')
    with pytest.raises(job_file.JobError, match="uv_on_copy must be true or false"):
        job_file.load(tmp_path / "job.toml")
