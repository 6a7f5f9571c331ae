"""Cameras (and sparse points) from a COLMAP model into the scene, used by the
``brdf.import_colmap`` operator and the job file.

Each registered image becomes a camera object, named after the image, in a
new collection. Importing again (the same model, or a newer one of the same
images) updates the cameras that already carry an image's name instead of
adding copies: one camera per image, its object name and collection kept.
Its custom properties carry what later steps need:
``brdf_image_name`` (the exact COLMAP image name, to match photos),
``brdf_width`` / ``brdf_height`` (pixels), ``brdf_pixel_aspect_x`` / ``_y``
(non-square pixels stand for fx != fy), and the lens:
``brdf_colmap_camera_model`` (e.g. "OPENCV"), ``brdf_colmap_params`` (the
model's parameters in COLMAP's order, floats) and ``brdf_colmap_distorted``.
The camera itself is the model's pinhole (its fx, fy, cx, cy and image
size); a distorted camera's photos are resampled to it with
``core.capture.undistort`` before use. Render size and pixel aspect are scene
settings in Blender, so a render from one of these cameras must first call
`set_render_to_camera`. The math is in ``core.capture.colmap``.
"""

import dataclasses
import pathlib

import bpy
import numpy as np
from mathutils import Matrix

from ..core.capture import cameras, colmap

COLLECTION_NAME = "COLMAP Cameras"
POINTS_NAME = "COLMAP Points"
# custom property of the sparse-point object (the model's path): a later import
# with points replaces that object's mesh instead of adding a second cloud
POINTS_PROPERTY = "brdf_colmap_points"


@dataclasses.dataclass(frozen=True)
class CameraImport:
    """What `import_model` did.

    cameras: one camera object per registered image, sorted by image name.
    created, updated: how many of them are new, and how many existed (matched by
        ``brdf_image_name``) and were updated.
    model_path: the model folder read (absolute; ``sparse`` resolves to ``sparse/0``).
    """

    cameras: list
    created: int
    updated: int
    model_path: str

    @property
    def folder_label(self) -> str:
        """The model folder named by its last two parts, e.g. "sparse/0"."""
        return model_label(self.model_path)

    def summary(self) -> str:
        """One sentence, e.g. "Imported 6 cameras from sparse/0"; "Updated 6 cameras
        from sparse/0" on a second import; "Imported 2 and updated 4 cameras ..."."""
        total = self.created + self.updated
        noun = "camera" if total == 1 else "cameras"
        if not self.updated:
            done = f"Imported {self.created} {noun}"
        elif not self.created:
            done = f"Updated {self.updated} {noun}"
        else:
            done = f"Imported {self.created} and updated {self.updated} {noun}"
        return f"{done} from {self.folder_label}"


def model_label(path) -> str:
    """A model folder named by its last two parts ("sparse/0", not "0"), "/"-joined."""
    parts = pathlib.PurePath(str(path)).parts
    return "/".join(parts[-2:]) if len(parts) > 1 else str(path)


def import_cameras(context_or_scene, model_dir, *, point_cloud: bool = False) -> list:
    """The camera objects of `import_model` (same arguments), sorted by image name."""
    return import_model(context_or_scene, model_dir, point_cloud=point_cloud).cameras


def import_model(context_or_scene, model_dir, *, point_cloud: bool = False) -> CameraImport:
    """One Blender camera per registered image of a COLMAP model, new or updated.

    context_or_scene: a ``bpy.types.Context`` (its scene is used) or a Scene.
    model_dir: the COLMAP model folder (cameras/images/points3D, .bin or .txt).
    point_cloud: also make a mesh object of the sparse points (vertices only,
        with their COLMAP colors as a point color attribute); an earlier
        import's point object in the scene gets the new points instead.

    A camera of the scene that carries an image's ``brdf_image_name`` is updated
    in place (pose, lens, size, the properties of the module docstring; its
    object name and collections kept); the other images get new camera
    objects, in the collection of the updated cameras, else in a new
    collection linked to the scene. Nothing else that existed is changed. If
    the scene has no active camera, the first camera becomes active and the
    render size and pixel aspect are set to it. Raises ValueError (one
    sentence), before any change, for a missing or unreadable model or an
    image name that two cameras of the scene carry.
    """
    scene = (
        context_or_scene
        if isinstance(context_or_scene, bpy.types.Scene)
        else context_or_scene.scene
    )
    if not str(model_dir).strip():
        raise ValueError("Choose a COLMAP model folder (holding cameras, images and points3D)")
    model = colmap.read_model(bpy.path.abspath(str(model_dir)))
    scale = cameras.view_scale([im.centre for im in model.images], model.xyz)

    existing = {}
    for obj in sorted(scene.objects, key=lambda o: o.name):
        if obj.type == "CAMERA" and "brdf_image_name" in obj:
            existing.setdefault(str(obj["brdf_image_name"]), []).append(obj)
    for im in model.images:
        if len(existing.get(im.name, ())) > 1:
            first, second = existing[im.name][:2]
            raise ValueError(f"Cameras {first.name} and {second.name} both carry COLMAP image "
                             f"{im.name}; delete one and import again")

    updated = [existing[im.name][0] for im in model.images if im.name in existing]
    collection = None
    if updated and updated[0].users_collection:
        collection = updated[0].users_collection[0]

    def target_collection():
        nonlocal collection
        if collection is None:
            collection = bpy.data.collections.new(COLLECTION_NAME)
            scene.collection.children.link(collection)
        return collection

    objects, created = [], 0
    for im in model.images:
        if im.name in existing:
            obj = existing[im.name][0]
        else:
            obj = bpy.data.objects.new(im.name, bpy.data.cameras.new(im.name))
            target_collection().objects.link(obj)
            created += 1
        _set_camera(obj, im, scale, model.path)
        objects.append(obj)

    if point_cloud and len(model.xyz):
        _set_point_cloud(scene, model, target_collection)

    if scene.camera is None:
        scene.camera = objects[0]
        set_render_to_camera(scene, objects[0])
    return CameraImport(cameras=objects, created=created, updated=len(objects) - created,
                        model_path=model.path)


def _set_camera(obj, im, scale: float, model_path: str) -> None:
    """Make camera object ``obj`` (and its camera data) the pinhole of COLMAP image ``im``."""
    intr = cameras.blender_intrinsics(im.fx, im.fy, im.cx, im.cy, im.width, im.height)
    data = obj.data
    data.type = "PERSP"
    data.lens_unit = "MILLIMETERS"
    data.sensor_fit = intr.sensor_fit
    data.sensor_width = intr.sensor_width
    data.sensor_height = intr.sensor_height
    data.lens = intr.lens
    data.shift_x = intr.shift_x
    data.shift_y = intr.shift_y
    data.clip_start = 1e-2 * scale
    data.clip_end = 1e2 * scale
    data.display_size = min(max(0.1 * scale, 0.01), 1000.0)

    obj.matrix_world = Matrix(
        cameras.camera_to_world(im.R_cam_from_world, im.t_cam_from_world).tolist()
    )
    obj["brdf_image_name"] = im.name
    obj["brdf_width"] = im.width
    obj["brdf_height"] = im.height
    obj["brdf_pixel_aspect_x"] = intr.pixel_aspect_x
    obj["brdf_pixel_aspect_y"] = intr.pixel_aspect_y
    obj["brdf_colmap_image_id"] = im.image_id
    obj["brdf_colmap_camera_model"] = im.camera_model
    obj["brdf_colmap_params"] = [float(p) for p in im.params]
    obj["brdf_colmap_distorted"] = im.distorted
    obj["brdf_colmap_model"] = model_path


def set_render_to_camera(scene, camera_object) -> None:
    """Set the scene's render size (100 %) and pixel aspect to an imported camera's photo.

    Needed before rendering or projecting through a camera made by
    `import_cameras`, because Blender keeps these per scene, not per camera.
    Raises ValueError if the object carries no ``brdf_width`` / ``brdf_height``.
    """
    try:
        width, height = int(camera_object["brdf_width"]), int(camera_object["brdf_height"])
    except KeyError:
        raise ValueError(
            f"Camera {camera_object.name!r} has no photo size (brdf_width, brdf_height); "
            "import it from COLMAP or set them"
        ) from None
    render = scene.render
    render.resolution_x = width
    render.resolution_y = height
    render.resolution_percentage = 100
    render.pixel_aspect_x = float(camera_object.get("brdf_pixel_aspect_x", 1.0))
    render.pixel_aspect_y = float(camera_object.get("brdf_pixel_aspect_y", 1.0))


def _set_point_cloud(scene, model, collection) -> None:
    """The sparse points as a mesh object: an earlier import's (``POINTS_PROPERTY``)
    gets the new mesh, else a new object goes into ``collection()``."""
    mesh = _point_cloud_mesh(model)
    old = next((o for o in scene.objects if o.type == "MESH" and POINTS_PROPERTY in o), None)
    if old is None:
        obj = bpy.data.objects.new(POINTS_NAME, mesh)
        collection().objects.link(obj)
    else:
        obj, previous = old, old.data
        obj.data = mesh
        if previous.users == 0:
            bpy.data.meshes.remove(previous)
    obj[POINTS_PROPERTY] = model.path


def _point_cloud_mesh(model):
    """(N,) sparse points as a vertex-only mesh with their sRGB colors."""
    mesh = bpy.data.meshes.new(POINTS_NAME)
    n = len(model.xyz)
    mesh.vertices.add(n)
    mesh.vertices.foreach_set("co", model.xyz.astype(np.float32).ravel())
    color = mesh.color_attributes.new("Col", "BYTE_COLOR", "POINT")
    rgba = np.ones((n, 4), dtype=np.float32)
    rgba[:, :3] = model.rgb / 255.0
    color.data.foreach_set("color_srgb", rgba.ravel())
    mesh.update()
    return mesh
