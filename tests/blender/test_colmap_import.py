"""brdf.import_colmap in pip ``bpy``: imported cameras reproject COLMAP's observations.

A synthetic COLMAP model (written by pycolmap, binary and text) is imported
through the operator; every 3D point is projected with Blender's own
``world_to_camera_view`` and compared with the 2D observation COLMAP computed
(``Camera.img_from_cam``). Both use image coordinates over [0, W] x [0, H]
(COLMAP pixel (0, 0) has its centre at (0.5, 0.5)), so x = u * W and
y = (1 - v) * H with no half-pixel offset.
"""

import types

import numpy as np
import pytest

bpy = pytest.importorskip("bpy")

from bpy_extras.object_utils import world_to_camera_view  # noqa: E402
from mathutils import Vector  # noqa: E402

from brdf_reconstruct.brdf_addon import colmap_import  # noqa: E402
from brdf_reconstruct.core.capture import cameras as camconv  # noqa: E402
from brdf_reconstruct.operators import import_colmap as import_colmap_op  # noqa: E402
from testkit import synthetic  # noqa: E402

pycolmap = pytest.importorskip("pycolmap")

# the operator (and the rest of the add-on) registered for every test
pytestmark = pytest.mark.usefixtures("registered")

OP = import_colmap_op.BRDF_OT_import_colmap


def _views():
    """Cameras around the origin: off-centre principal points, fx != fy both ways,
    one portrait image, a square image seen from above, a zero-distortion radial model."""
    return [
        ("a.jpg", "PINHOLE", [800, 860, 300, 260], 640, 480,
         *camconv.look_at([4, 0.5, 1], [0, 0, 0])),
        ("b_portrait.jpg", "PINHOLE", [700, 650, 250, 300], 480, 640,
         *camconv.look_at([0.3, 4, 1.5], [0, 0, 0.1])),
        ("c.jpg", "SIMPLE_PINHOLE", [900, 400, 300], 800, 600,
         *camconv.look_at([-3, -3, 0.5], [0.1, 0, 0])),
        ("d.jpg", "SIMPLE_RADIAL", [1000, 530, 370, 0.0], 1024, 768,
         *camconv.look_at([-4, 1, -1], [0, 0, 0])),
        ("sub/e.jpg", "PINHOLE", [600, 600, 200, 320], 512, 512,
         *camconv.look_at([0.5, -0.5, 4.5], [0, 0, 0])),
    ]  # fmt: skip


@pytest.fixture(scope="module")
def models(tmp_path_factory):
    rng = np.random.default_rng(0)
    xyz = rng.uniform(-1, 1, (200, 3))
    rgb = rng.integers(0, 256, (200, 3), dtype=np.uint8)
    rec = synthetic.synthetic_reconstruction(_views(), xyz, rgb)
    root = tmp_path_factory.mktemp("colmap")
    (root / "bin").mkdir()
    (root / "txt").mkdir()
    rec.write(str(root / "bin"))
    rec.write_text(str(root / "txt"))
    assert {p.suffix for p in (root / "bin").iterdir()} == {".bin"}
    assert {p.suffix for p in (root / "txt").iterdir()} == {".txt"}
    return {"bin": root / "bin", "txt": root / "txt"}


def _imported_cameras(collection_name=colmap_import.COLLECTION_NAME):
    return [o for o in bpy.data.collections[collection_name].objects if o.type == "CAMERA"]


def _reprojection_errors(model_dir):
    """Pixel distances between Blender's projection and COLMAP's observations, per camera."""
    rec = pycolmap.Reconstruction(str(model_dir))  # read independently of core.capture.colmap
    by_name = {rec.image(i).name: rec.image(i) for i in rec.reg_image_ids()}
    scene = bpy.context.scene
    errors = {}
    for obj in _imported_cameras():
        image = by_name[obj["brdf_image_name"]]
        camera = rec.camera(image.camera_id)
        colmap_import.set_render_to_camera(scene, obj)
        assert (scene.render.resolution_x, scene.render.resolution_y) == (
            camera.width,
            camera.height,
        )
        obs = image.get_observation_points2D()
        assert len(obs) > 100
        err = []
        for p2d in obs:
            u, v, depth = world_to_camera_view(scene, obj, Vector(rec.point3D(p2d.point3D_id).xyz))
            assert depth > 0
            blender_px = np.array([u * camera.width, (1.0 - v) * camera.height])
            err.append(np.linalg.norm(blender_px - p2d.xy))
        errors[image.name] = np.array(err)
    return errors


@pytest.mark.parametrize("kind", ["bin", "txt"])
def test_reprojection_through_blender(models, kind):
    assert bpy.ops.brdf.import_colmap(directory=str(models[kind])) == {"FINISHED"}
    errors = _reprojection_errors(models[kind])
    assert sorted(errors) == sorted(v[0] for v in _views())
    every = np.concatenate(list(errors.values()))
    print(
        f"\n{kind}: mean {every.mean():.2e} px, max {every.max():.2e} px over {every.size} "
        "observations; per camera max: "
        + ", ".join(f"{name} {e.max():.1e}" for name, e in sorted(errors.items()))
    )
    assert every.mean() < 0.5  # the brief's bound
    assert every.max() < 0.01  # float32 storage in Blender is ~1e-4 px; a convention slip is >= 0.5


def test_intrinsics_and_properties(models):
    bpy.ops.brdf.import_colmap(directory=str(models["bin"]))
    cams = {o["brdf_image_name"]: o for o in _imported_cameras()}
    assert set(cams) == {v[0] for v in _views()}
    a, b, e = cams["a.jpg"], cams["b_portrait.jpg"], cams["sub/e.jpg"]
    assert e.name == "sub/e.jpg"
    assert (a["brdf_width"], a["brdf_height"]) == (640, 480)
    assert (b["brdf_width"], b["brdf_height"]) == (480, 640)
    assert a.data.sensor_fit == "HORIZONTAL" and b.data.sensor_fit == "VERTICAL"
    assert e.data.sensor_fit == "HORIZONTAL"
    # fx < fy: pixels wider than tall; fx > fy: taller than wide
    assert (a["brdf_pixel_aspect_x"], a["brdf_pixel_aspect_y"]) == pytest.approx((860 / 800, 1))
    assert (b["brdf_pixel_aspect_x"], b["brdf_pixel_aspect_y"]) == pytest.approx((1, 700 / 650))
    assert a.data.shift_x == pytest.approx((320 - 300) / 640)
    assert not any(o["brdf_colmap_distorted"] for o in cams.values())
    assert all(o.data.type == "PERSP" for o in cams.values())


def test_first_camera_becomes_active_in_an_empty_scene(models):
    scene = bpy.context.scene
    assert scene.camera is None
    bpy.ops.brdf.import_colmap(directory=str(models["txt"]))
    assert scene.camera["brdf_image_name"] == "a.jpg"  # sorted by image name
    assert (scene.render.resolution_x, scene.render.resolution_y) == (640, 480)
    assert scene.render.resolution_percentage == 100
    assert scene.render.pixel_aspect_x == pytest.approx(860 / 800)


def test_existing_scene_camera_and_render_settings_are_kept(models):
    scene = bpy.context.scene
    mine = bpy.data.objects.new("Mine", bpy.data.cameras.new("Mine"))
    scene.collection.objects.link(mine)
    scene.camera = mine
    scene.render.resolution_x, scene.render.resolution_y = 1234, 567
    bpy.ops.brdf.import_colmap(directory=str(models["bin"]))
    assert scene.camera == mine
    assert (scene.render.resolution_x, scene.render.resolution_y) == (1234, 567)


def _snapshot(objects):
    def data(o):
        d = o.data
        return None if d is None else (d.name, d.lens, d.sensor_width, d.shift_x, d.shift_y)

    return {
        o.name: (
            [list(row) for row in o.matrix_world],
            # ID property arrays compare by identity: compare their values
            {k: v.to_list() if hasattr(v, "to_list") else v for k, v in o.items()},
            data(o),
            [c.name for c in o.users_collection],
        )
        for o in objects
    }


def _moved_views():
    """The same image names as `_views`, every camera elsewhere and with another lens:
    a re-run of the reconstruction."""
    return [
        (name, model, [p * 1.05 for p in params], w, h,
         *camconv.look_at(np.array(centre) * 1.1 + [0.1, -0.2, 0.05], [0.05, 0, 0]))
        for (name, model, params, w, h, _R, _t), centre in zip(
            _views(), [[4, 0.5, 1], [0.3, 4, 1.5], [-3, -3, 0.5], [-4, 1, -1], [0.5, -0.5, 4.5]],
            strict=True)
    ]


def _write_model(folder, views):
    rng = np.random.default_rng(0)
    xyz = rng.uniform(-1, 1, (200, 3))
    rgb = rng.integers(0, 256, (200, 3), dtype=np.uint8)
    folder.mkdir(parents=True)
    synthetic.synthetic_reconstruction(views, xyz, rgb).write(str(folder))
    return folder


def _import_reporting(folder, point_cloud=False):
    fake = _FakeOperator(directory=str(folder), point_cloud=point_cloud, reports=[])
    assert OP.execute(fake, bpy.context) == {"FINISHED"}
    ((kind, message),) = fake.reports
    return kind, message


def _expected_matrix_world(image):
    """Blender's camera-to-world for a COLMAP image, from pycolmap's pose alone: the
    camera sits at C = -R^T t; Blender's camera x, y, z are COLMAP's x, -y, -z."""
    pose = image.cam_from_world()
    R, t = pose.rotation.matrix(), pose.translation
    M = np.eye(4)
    M[:3, :3] = R.T @ np.diag([1.0, -1.0, -1.0])
    M[:3, 3] = -R.T @ t
    return M


def _camera_objects():
    return [o for o in bpy.data.objects if o.type == "CAMERA"]


def test_importing_twice_updates_the_cameras_instead_of_copying_them(tmp_path):
    """One camera per image: the second import (a re-run with moved cameras) updates the
    cameras of the first, names and collection kept, poses and lenses the new model's;
    the scan, the scene camera and the render size are left alone."""
    first_model = _write_model(tmp_path / "first" / "sparse" / "0", _views())
    second_model = _write_model(tmp_path / "second" / "sparse" / "0", _moved_views())
    scan = bpy.data.objects.new("Scan", None)
    bpy.context.scene.collection.objects.link(scan)
    scan_before = _snapshot([scan])
    assert _import_reporting(first_model) == ({"INFO"}, "Imported 5 cameras from sparse/0")
    first = _imported_cameras()
    names = sorted(o.name for o in first)
    render_before = (bpy.context.scene.render.resolution_x, bpy.context.scene.camera.name)

    assert _import_reporting(second_model) == ({"INFO"}, "Updated 5 cameras from sparse/0")
    assert (bpy.context.scene.render.resolution_x, bpy.context.scene.camera.name) == render_before
    assert sorted(_camera_objects(), key=lambda o: o.name) == sorted(first, key=lambda o: o.name)
    assert sorted(o.name for o in _camera_objects()) == names  # no "a.jpg.001"
    assert [c.name for c in bpy.data.collections] == [colmap_import.COLLECTION_NAME]
    rec = pycolmap.Reconstruction(str(second_model))
    by_name = {rec.image(i).name: rec.image(i) for i in rec.reg_image_ids()}
    old = pycolmap.Reconstruction(str(first_model))
    old_a = next(old.image(i) for i in old.reg_image_ids() if old.image(i).name == "a.jpg")
    assert np.abs(_expected_matrix_world(old_a) - _expected_matrix_world(by_name["a.jpg"])
                  ).max() > 0.1  # the second model really moved the cameras
    for obj in first:
        np.testing.assert_allclose(np.array(obj.matrix_world),
                                   _expected_matrix_world(by_name[obj["brdf_image_name"]]),
                                   atol=1e-5)
        assert obj["brdf_colmap_model"] == str(second_model)
    # the new lenses too, through Blender's own projection (this sets the render size)
    errors = np.concatenate(list(_reprojection_errors(second_model).values()))
    assert errors.max() < 0.01
    assert _snapshot([scan]) == scan_before


def test_reimport_keeps_a_renamed_camera_and_adds_only_new_images(tmp_path):
    """Matched by the COLMAP image name the camera carries, not its object name; an image
    new to the model gets a camera in the collection of the others."""
    base = _write_model(tmp_path / "base" / "sparse" / "0", _views()[:3])
    grown = _write_model(tmp_path / "grown" / "sparse" / "1", _views())
    colmap_import.import_cameras(bpy.context.scene, base)
    renamed = next(o for o in _camera_objects() if o["brdf_image_name"] == "a.jpg")
    renamed.name = "Front"
    assert _import_reporting(grown) == ({"INFO"}, "Imported 2 and updated 3 cameras from "
                                                  "sparse/1")
    assert len(_camera_objects()) == 5
    assert sorted(o.name for o in _camera_objects()) == sorted(
        ["Front", "b_portrait.jpg", "c.jpg", "d.jpg", "sub/e.jpg"])
    assert bpy.data.objects["Front"]["brdf_image_name"] == "a.jpg"
    assert len(_imported_cameras()) == 5


def test_two_cameras_carrying_one_image_name_stop_the_import(tmp_path):
    model = _write_model(tmp_path / "sparse" / "0", _views())
    cams = colmap_import.import_cameras(bpy.context.scene, model)
    copy = cams[0].copy()
    bpy.context.scene.collection.objects.link(copy)
    before = _snapshot(_camera_objects())
    with pytest.raises(ValueError, match="both carry COLMAP image a.jpg; delete one") as error:
        colmap_import.import_cameras(bpy.context.scene, model)
    assert "\n" not in str(error.value)
    assert _snapshot(_camera_objects()) == before


def test_point_cloud_imported_twice_is_one_object(tmp_path):
    model = _write_model(tmp_path / "sparse" / "0", _views())
    _import_reporting(model, point_cloud=True)
    _import_reporting(model, point_cloud=True)
    clouds = [o for o in bpy.data.objects if o.type == "MESH"]
    assert len(clouds) == 1 and len(clouds[0].data.vertices) == 200
    assert len(bpy.data.meshes) == 1  # the first cloud's mesh went with it


def test_model_label_names_the_last_two_parts():
    assert colmap_import.model_label("/captures/statue/sparse/0") == "sparse/0"
    assert colmap_import.model_label("/captures/statue/sparse/0/") == "sparse/0"
    assert colmap_import.model_label("model") == "model"


def test_point_cloud(models):
    bpy.ops.brdf.import_colmap(directory=str(models["bin"]), point_cloud=True)
    points = bpy.data.collections[colmap_import.COLLECTION_NAME].objects[colmap_import.POINTS_NAME]
    rec = pycolmap.Reconstruction(str(models["bin"]))
    ids = sorted(rec.point3D_ids())
    xyz = np.array([rec.point3D(i).xyz for i in ids])
    rgb = np.array([rec.point3D(i).color for i in ids])
    co = np.array([v.co[:] for v in points.data.vertices])
    order = np.lexsort(co.T)
    np.testing.assert_allclose(co[order], xyz[np.lexsort(xyz.T)], atol=1e-6)
    srgb = np.array([c.color_srgb[:3] for c in points.data.color_attributes["Col"].data])
    np.testing.assert_allclose(srgb[order] * 255, rgb[np.lexsort(xyz.T)], atol=0.51)


def test_no_point_cloud_by_default(models):
    bpy.ops.brdf.import_colmap(directory=str(models["bin"]))
    collection = bpy.data.collections[colmap_import.COLLECTION_NAME]
    assert all(o.type == "CAMERA" for o in collection.objects)


def test_plain_function_for_the_batch_runner(models):
    cams = colmap_import.import_cameras(bpy.context.scene, models["txt"])
    assert [o["brdf_image_name"] for o in cams] == sorted(v[0] for v in _views())
    assert all(o.name in bpy.context.scene.objects for o in cams)
    more = colmap_import.import_cameras(bpy.context, models["bin"])
    assert len(more) == len(cams)


def test_distortion_is_flagged(tmp_path):
    view = ("w.jpg", "OPENCV", [700, 700, 250, 200, 0.05, 0, 0, 0], 500, 400)
    synthetic.synthetic_reconstruction(
        [(*view, *camconv.look_at([3, 0, 0], [0, 0, 0]))], np.zeros((0, 3))
    ).write(str(tmp_path))
    assert bpy.ops.brdf.import_colmap(directory=str(tmp_path)) == {"FINISHED"}
    (cam,) = _imported_cameras()
    assert cam["brdf_colmap_distorted"] and cam["brdf_colmap_camera_model"] == "OPENCV"


class _FakeOperator(types.SimpleNamespace):
    def report(self, kind, message):
        self.reports.append((kind, message))


@pytest.mark.parametrize("directory", ["missing", ""])
def test_bad_folder_cancels_with_one_line(tmp_path, directory):
    path = str(tmp_path / directory) if directory else ""
    fake = _FakeOperator(directory=path, point_cloud=False, reports=[])
    assert OP.execute(fake, bpy.context) == {"CANCELLED"}
    ((kind, message),) = fake.reports
    assert kind == {"ERROR"} and "\n" not in message and message
    with pytest.raises(RuntimeError, match="COLMAP model") as err:
        bpy.ops.brdf.import_colmap(directory=path)
    assert len(str(err.value).strip().splitlines()) == 1
    assert len(bpy.data.objects) == 0 and len(bpy.data.collections) == 0


def test_folder_without_model_cancels(tmp_path):
    with pytest.raises(RuntimeError, match="No COLMAP model"):
        bpy.ops.brdf.import_colmap(directory=str(tmp_path))
    assert len(bpy.data.collections) == 0


def test_set_render_to_camera_needs_an_imported_camera():
    plain = bpy.data.objects.new("Plain", bpy.data.cameras.new("Plain"))
    with pytest.raises(ValueError, match="brdf_width"):
        colmap_import.set_render_to_camera(bpy.context.scene, plain)


def test_operator_declares_undo_and_a_folder_browser():
    assert {"REGISTER", "UNDO"} <= OP.bl_options
    assert OP.bl_idname == "brdf.import_colmap"
    directory = bpy.ops.brdf.import_colmap.get_rna_type().properties["directory"]
    assert directory.subtype == "DIR_PATH"
    assert "invoke" in OP.__dict__  # opens the file browser (fileselect_add)


# --------------------------------------------------------------------------- lens parameters


def test_distorted_camera_carries_its_params_and_warns_of_undistortion(tmp_path):
    params = [700, 710, 250, 200, 0.05, -0.01, 0.001, 0.002]
    views = [
        ("d.jpg", "OPENCV", params, 500, 400, *camconv.look_at([3, 0, 0], [0, 0, 0])),
        ("p.jpg", "PINHOLE", [600, 600, 250, 200], 500, 400,
         *camconv.look_at([0, 3, 0], [0, 0, 0])),
    ]
    synthetic.synthetic_reconstruction(views, np.zeros((0, 3))).write(str(tmp_path))
    fake = _FakeOperator(directory=str(tmp_path), point_cloud=False, reports=[])
    assert OP.execute(fake, bpy.context) == {"FINISHED"}
    ((kind, message),) = fake.reports
    assert kind == {"WARNING"} and "\n" not in message
    assert message.startswith("1 of 2 cameras have lens distortion")
    assert "undistorted automatically" in message
    cams = {o["brdf_image_name"]: o for o in _imported_cameras()}
    assert list(cams["d.jpg"]["brdf_colmap_params"]) == pytest.approx(params, abs=0)
    assert list(cams["p.jpg"]["brdf_colmap_params"]) == [600, 600, 250, 200]
    assert all(isinstance(v, float) for v in cams["d.jpg"]["brdf_colmap_params"])


def _shared_camera_model(path):
    """Two COLMAP cameras (PINHOLE 640 x 480, OPENCV 500 x 400) shared by four images,
    built with pycolmap directly; written binary to `path`. Returns the world points."""
    cameras = {
        1: ("PINHOLE", [800.0, 820.0, 330.0, 250.0], 640, 480),
        2: ("OPENCV", [600.0, 610.0, 245.0, 210.0, -0.1, 0.02, 0.001, -0.002], 500, 400),
    }
    images = [
        ("p1.jpg", 1, camconv.look_at([4, 0.5, 1], [0, 0, 0])),
        ("o1.jpg", 2, camconv.look_at([0.3, 4, 1.5], [0, 0, 0.1])),
        ("p2.jpg", 1, camconv.look_at([-3, -3, 0.5], [0.1, 0, 0])),
        ("o2.jpg", 2, camconv.look_at([-4, 1, -1], [0, 0, 0])),
    ]
    xyz = np.random.default_rng(5).uniform(-1, 1, (150, 3))
    rec = pycolmap.Reconstruction()
    for cid, (model, params, w, h) in cameras.items():
        camera = pycolmap.Camera.create_from_model_name(cid, model, 1.0, w, h)
        camera.params = params
        rec.add_camera_with_trivial_rig(camera)
    tracks = [[] for _ in xyz]
    for k, (name, cid, (R, t)) in enumerate(images, start=1):
        uv = rec.camera(cid).img_from_cam(xyz @ R.T + t)
        image = pycolmap.Image(name=name, keypoints=uv, camera_id=cid, image_id=k)
        rec.add_image_with_trivial_frame(image, pycolmap.Rigid3d(pycolmap.Rotation3d(R), t))
        for j in range(len(xyz)):
            tracks[j].append(pycolmap.TrackElement(k, j))
    for j, track in enumerate(tracks):
        rec.add_point3D(xyz[j], pycolmap.Track(track), np.zeros(3, np.uint8))
    rec.write(str(path))
    return xyz


def _blender_pixels(obj, xyz):
    """(N, 2) pixels of world points through a Blender camera (world_to_camera_view)."""
    scene = bpy.context.scene
    colmap_import.set_render_to_camera(scene, obj)
    w, h = scene.render.resolution_x, scene.render.resolution_y
    out = []
    for p in xyz:
        u, v, depth = world_to_camera_view(scene, obj, Vector(p))
        assert depth > 0
        out.append([u * w, (1.0 - v) * h])
    return np.array(out)


def test_several_shared_cameras_give_each_image_its_own_intrinsics_and_size(tmp_path):
    xyz = _shared_camera_model(tmp_path)
    rec = pycolmap.Reconstruction(str(tmp_path))
    assert len(rec.cameras) == 2 and len(rec.images) == 4
    imported = colmap_import.import_cameras(bpy.context.scene, tmp_path)
    cams = {o["brdf_image_name"]: o for o in imported}
    assert sorted(cams) == ["o1.jpg", "o2.jpg", "p1.jpg", "p2.jpg"]
    for image in (rec.image(i) for i in rec.reg_image_ids()):
        obj, camera = cams[image.name], rec.camera(image.camera_id)
        assert (obj["brdf_width"], obj["brdf_height"]) == (camera.width, camera.height)
        assert list(obj["brdf_colmap_params"]) == list(camera.params)
        assert obj["brdf_colmap_camera_model"] == camera.model.name
        assert obj["brdf_colmap_distorted"] == (camera.model.name == "OPENCV")
        pose = image.cam_from_world()
        cam_pts = xyz @ pose.rotation.matrix().T + pose.translation
        fx, fy, cx, cy = camera.params[:4]  # both models start with fx, fy, cx, cy
        pinhole = np.column_stack(
            [fx * cam_pts[:, 0] / cam_pts[:, 2] + cx, fy * cam_pts[:, 1] / cam_pts[:, 2] + cy]
        )
        px = _blender_pixels(obj, xyz)
        np.testing.assert_allclose(px, pinhole, rtol=0, atol=0.01)  # the model's own pinhole
        observed = np.array([p.xy for p in image.points2D])
        if camera.model.name == "PINHOLE":
            np.testing.assert_allclose(px, observed, rtol=0, atol=0.01)
        else:  # the lens moves COLMAP's observations off the pinhole; undistortion's job
            assert np.abs(px - observed).max() > 1.0
    # the two images on camera 1 share one size, the two on camera 2 another
    assert {(o["brdf_width"], o["brdf_height"]) for o in cams.values()} == {(640, 480), (500, 400)}
    assert cams["p1.jpg"].data.lens == pytest.approx(cams["p2.jpg"].data.lens)
    assert cams["o1.jpg"].data.lens != pytest.approx(cams["p1.jpg"].data.lens)


def test_only_registered_images_become_cameras_even_without_points(tmp_path):
    photos = tmp_path / "photos"
    photos.mkdir()
    names = ["a.jpg", "b.jpg", "c.jpg", "d.jpg", "e.jpg"]
    for name in names:
        (photos / name).write_bytes(b"")
    views = [
        ("a.jpg", "PINHOLE", [500, 500, 320, 240], 640, 480,
         *camconv.look_at([4, 0, 1], [0, 0, 0])),
        ("b.jpg", "PINHOLE", [500, 500, 320, 240], 640, 480,
         *camconv.look_at([0, 4, 1], [0, 0, 0])),
        # looks away from every point: registered, but with no observation
        ("c.jpg", "PINHOLE", [500, 500, 320, 240], 640, 480,
         *camconv.look_at([5, 5, 5], [10, 11, 12])),
    ]  # fmt: skip
    xyz = np.random.default_rng(2).uniform(-1, 1, (60, 3))
    rec = synthetic.synthetic_reconstruction(views, xyz)
    rec.deregister_frame(rec.image(2).frame_id)  # b.jpg failed to register in SfM
    model = tmp_path / "sparse"
    model.mkdir()
    rec.write_text(str(model))
    assert "b.jpg" not in (model / "images.txt").read_text()
    cams = colmap_import.import_cameras(bpy.context.scene, model)
    assert [o["brdf_image_name"] for o in cams] == ["a.jpg", "c.jpg"]  # of 5 photos
    c = cams[1]
    assert pycolmap.Reconstruction(str(model)).image(3).num_points3D == 0
    R, t = views[2][5], views[2][6]
    np.testing.assert_allclose(np.array(c.matrix_world), camconv.camera_to_world(R, t), atol=1e-6)
    ahead = camconv.camera_centre(R, t) + np.random.default_rng(3).uniform(4, 6, (20, 3))
    px = _blender_pixels(c, ahead)
    camera = pycolmap.Camera.create_from_model_name(1, "PINHOLE", 1.0, 640, 480)
    camera.params = [500, 500, 320, 240]
    np.testing.assert_allclose(px, camera.img_from_cam(ahead @ R.T + t), rtol=0, atol=0.01)


# ------------------------------------------------------------------- meshes in COLMAP's frame


def _ellipsoid():
    """A closed triangle mesh around the model's points, with no symmetry that an axis
    swap could hide: (V, 3) float64 vertices and (F, 3) int faces."""
    lat = np.linspace(0, np.pi, 9)[1:-1]
    lon = np.linspace(0, 2 * np.pi, 13)[:-1]
    la, lo = np.meshgrid(lat, lon, indexing="ij")
    ring = np.stack([np.sin(la) * np.cos(lo), np.sin(la) * np.sin(lo), np.cos(la)], -1)
    v = np.concatenate([[[0, 0, 1]], ring.reshape(-1, 3), [[0, 0, -1]]])
    v = v * [0.9, 0.7, 0.5] + [0.15, -0.2, 0.1]
    n_lat, n_lon = la.shape
    idx = 1 + np.arange(n_lat * n_lon).reshape(n_lat, n_lon)
    faces = [[0, idx[0, j], idx[0, (j + 1) % n_lon]] for j in range(n_lon)]
    for i in range(n_lat - 1):
        for j in range(n_lon):
            a, b = idx[i, j], idx[i, (j + 1) % n_lon]
            c, d = idx[i + 1, j], idx[i + 1, (j + 1) % n_lon]
            faces += [[a, c, b], [b, c, d]]
    last = len(v) - 1
    faces += [[last, idx[-1, (j + 1) % n_lon], idx[-1, j]] for j in range(n_lon)]
    return v, np.array(faces)


def _write_mesh(path, v, f):
    if path.suffix == ".obj":
        lines = [f"v {x:.9f} {y:.9f} {z:.9f}" for x, y, z in v]
        lines += [f"f {a + 1} {b + 1} {c + 1}" for a, b, c in f]
    elif path.suffix == ".ply":
        lines = ["ply", "format ascii 1.0", f"element vertex {len(v)}", "property float x",
                 "property float y", "property float z", f"element face {len(f)}",
                 "property list uchar int vertex_indices", "end_header"]  # fmt: skip
        lines += [f"{x:.9f} {y:.9f} {z:.9f}" for x, y, z in v]
        lines += [f"3 {a} {b} {c}" for a, b, c in f]
    else:
        lines = ["solid colmap"]
        for tri in f:
            lines += ["facet normal 0 0 0", "outer loop"]
            lines += [f"vertex {x:.9f} {y:.9f} {z:.9f}" for x, y, z in v[tri]]
            lines += ["endloop", "endfacet"]
        lines.append("endsolid colmap")
    path.write_text("\n".join(lines) + "\n")


IDENTITY_AXES = {
    ".obj": (bpy.ops.wm.obj_import, {"forward_axis": "Y", "up_axis": "Z", "global_scale": 1.0}),
    ".ply": (bpy.ops.wm.ply_import, {"forward_axis": "Y", "up_axis": "Z", "global_scale": 1.0,
                                     "use_scene_unit": False}),
    ".stl": (bpy.ops.wm.stl_import, {"forward_axis": "Y", "up_axis": "Z", "global_scale": 1.0,
                                     "use_scene_unit": False}),
}  # fmt: skip


def _import_mesh(path, **kwargs):
    before = set(bpy.data.objects)
    importer = IDENTITY_AXES[path.suffix][0]
    assert importer(filepath=str(path), **kwargs) == {"FINISHED"}
    (obj,) = set(bpy.data.objects) - before
    co = np.empty(3 * len(obj.data.vertices), np.float32)
    obj.data.vertices.foreach_get("co", co)
    M = np.array(obj.matrix_world)
    return co.reshape(-1, 3).astype(np.float64) @ M[:3, :3].T + M[:3, 3]


def _matched(world, reference):
    """For each imported vertex, the index of the file vertex it came from (nearest)."""
    d = np.linalg.norm(world[:, None, :] - reference[None, :, :], axis=2)
    return d.argmin(axis=1), d.min(axis=1)


@pytest.mark.parametrize("suffix", [".obj", ".ply", ".stl"])
def test_mesh_in_colmap_world_frame_projects_like_pycolmap(models, tmp_path, suffix):
    v, f = _ellipsoid()
    path = tmp_path / f"scan{suffix}"
    _write_mesh(path, v, f)
    colmap_import.import_cameras(bpy.context.scene, models["bin"])
    world = _import_mesh(path, **IDENTITY_AXES[suffix][1])
    which, dist = _matched(world, v)
    assert dist.max() < 1e-6 and set(which) == set(range(len(v)))  # coordinates unchanged
    rec = pycolmap.Reconstruction(str(models["bin"]))
    by_name = {rec.image(i).name: rec.image(i) for i in rec.reg_image_ids()}
    worst = 0.0
    for obj in _imported_cameras():
        image = by_name[obj["brdf_image_name"]]
        cam_pts = np.array([image.cam_from_world() * p for p in world])
        expected = rec.camera(image.camera_id).img_from_cam(cam_pts)
        err = np.abs(_blender_pixels(obj, world) - expected).max()
        worst = max(worst, err)
    print(f"\n{suffix}: {len(world)} vertices, max pixel difference {worst:.1e}")
    assert worst < 0.01


def test_obj_default_axes_would_move_the_mesh_off_the_cameras(models, tmp_path):
    v, f = _ellipsoid()
    path = tmp_path / "scan.obj"
    _write_mesh(path, v, f)
    colmap_import.import_cameras(bpy.context.scene, models["bin"])
    world = _import_mesh(path)  # the OBJ importer's defaults: forward -Z, up Y
    # file (x, y, z) -> Blender (x, -z, y): a quarter turn about x
    which, dist = _matched(world, v @ np.array([[1, 0, 0], [0, 0, 1], [0, -1, 0]]))
    assert dist.max() < 1e-6
    assert _matched(world, v)[1].max() > 0.1
    rec = pycolmap.Reconstruction(str(models["bin"]))
    by_name = {rec.image(i).name: rec.image(i) for i in rec.reg_image_ids()}
    obj = _imported_cameras()[0]
    image = by_name[obj["brdf_image_name"]]
    truth = rec.camera(image.camera_id).img_from_cam(
        np.array([image.cam_from_world() * p for p in v[which]])
    )
    assert np.linalg.norm(_blender_pixels(obj, world) - truth, axis=1).max() > 10.0
