"""The scene's list of lit photos: adding entries and matching each to its camera.

Each photo is matched to a camera by image name: the camera's
``brdf_image_name`` (set by the COLMAP import), or else its object name,
compared with the photo's file name, first whole and then without the
extension (a lit ``0012.exr`` matches COLMAP's ``0012.jpg``). A photo that
matches no camera, or more than one, is listed and not added: never guessed.
"""

import os

import bpy

# what a new entry takes from the last one: often all photos share one light
SHARED = ("light_source", "sun", "direction", "probe_path", "probe_center", "probe_radius",
          "when", "utc_offset", "latitude", "longitude", "north_offset", "time_from_exif",
          "place_from_exif", "irradiance", "color_space")


def _stem(name: str) -> str:
    return os.path.splitext(os.path.basename(name))[0]


def camera_names(obj) -> tuple[str, str]:
    """(image name, object name) a photo may match for a camera object."""
    return str(obj.get("brdf_image_name", "")), obj.name


def match_camera(scene, filename: str):
    """The one camera object of ``scene`` matching ``filename``; ValueError otherwise."""
    base = os.path.basename(filename)
    cameras = [o for o in scene.objects if o.type == "CAMERA"]
    for key in (lambda n: n, _stem):
        hits = [c for c in cameras
                if key(base) in {key(n) for n in camera_names(c) if n}]
        if len(hits) == 1:
            return hits[0]
        if len(hits) > 1:
            names = ", ".join(sorted(c.name for c in hits))
            raise ValueError(f"photo {base} matches several cameras ({names})")
    raise ValueError(f"photo {base} matches no camera by image name")


def add_photos(scene, paths) -> tuple[list, list[str]]:
    """Append one ``scene.brdf.photos`` entry per matched path.

    Returns (added entries, one message per photo not added). A path already in
    the list is not added twice. New entries take the light (with its date,
    place or probe), irradiance and color space of the last entry (often all
    photos share one light), else the scene's first Sun object.
    """
    settings = scene.brdf
    existing = {bpy.path.abspath(p.filepath) for p in settings.photos}
    template = settings.photos[-1] if len(settings.photos) else None
    suns = [o for o in scene.objects if o.type == "LIGHT" and o.data.type == "SUN"]
    added, unmatched = [], []
    for path in paths:
        if bpy.path.abspath(path) in existing:
            unmatched.append(f"photo {os.path.basename(path)} is already in the list")
            continue
        try:
            camera = match_camera(scene, path)
        except ValueError as error:
            unmatched.append(str(error))
            continue
        entry = settings.photos.add()
        entry.name = os.path.basename(path)
        entry.filepath = path
        entry.camera = camera
        if template is not None:
            for key in SHARED:
                setattr(entry, key, getattr(template, key))
        elif suns:
            entry.sun = suns[0]
        added.append(entry)
    settings.active_photo = max(len(settings.photos) - 1, 0)
    return added, unmatched
