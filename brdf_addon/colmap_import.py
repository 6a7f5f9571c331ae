"""Cameras (and sparse points) from a COLMAP model into the scene, used by the
``brdf.import_colmap`` operator and the job file.

Each registered image becomes a camera object, named after the image, in a
new collection. Its custom properties carry what later steps need:
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

import bpy
import numpy as np
from mathutils import Matrix

from ..core.capture import cameras, colmap

COLLECTION_NAME = "COLMAP Cameras"
POINTS_NAME = "COLMAP Points"


def import_cameras(context_or_scene, model_dir, *, point_cloud: bool = False) -> list:
    """Create one Blender camera per registered image of a COLMAP model.

    context_or_scene: a ``bpy.types.Context`` (its scene is used) or a Scene.
    model_dir: the COLMAP model folder (cameras/images/points3D, .bin or .txt).
    point_cloud: also create a mesh object of the sparse points (vertices
        only, with their COLMAP colours as a point colour attribute).

    Returns the camera objects, sorted by image name, in a new collection
    linked to the scene; nothing that existed before is changed. If the scene
    has no active camera, the first imported one becomes active and the
    render size and pixel aspect are set to it. Raises ValueError (one
    sentence) for a missing or unreadable model.
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

    collection = bpy.data.collections.new(COLLECTION_NAME)
    scene.collection.children.link(collection)
    objects = []
    for im in model.images:
        intr = cameras.blender_intrinsics(im.fx, im.fy, im.cx, im.cy, im.width, im.height)
        data = bpy.data.cameras.new(im.name)
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

        obj = bpy.data.objects.new(im.name, data)
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
        obj["brdf_colmap_model"] = model.path
        collection.objects.link(obj)
        objects.append(obj)

    if point_cloud and len(model.xyz):
        collection.objects.link(_point_cloud_object(model))

    if scene.camera is None:
        scene.camera = objects[0]
        set_render_to_camera(scene, objects[0])
    return objects


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


def _point_cloud_object(model):
    mesh = bpy.data.meshes.new(POINTS_NAME)
    n = len(model.xyz)
    mesh.vertices.add(n)
    mesh.vertices.foreach_set("co", model.xyz.astype(np.float32).ravel())
    colour = mesh.color_attributes.new("Col", "BYTE_COLOR", "POINT")
    rgba = np.ones((n, 4), dtype=np.float32)
    rgba[:, :3] = model.rgb / 255.0
    colour.data.foreach_set("color_srgb", rgba.ravel())
    mesh.update()
    return bpy.data.objects.new(POINTS_NAME, mesh)
