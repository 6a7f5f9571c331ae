"""The batch job file (TOML): the text form of what the panel holds.

See docs/user-guide.md (the job-file reference) for the format. Paths are relative
to the job file. :func:`load` parses and checks it (no bpy calls);
:func:`apply` builds the scene through the same operators the panel uses.

Angles are degrees in the job file, as the panel shows them: ``peak_max_angle``
in [settings] and ``north_offset`` in [photo.sun]. Their properties are Blender
``ANGLE`` properties holding radians, so :func:`apply` converts, and checks the
job's degrees against the property's range in degrees.
"""

from __future__ import annotations

import dataclasses
import math
import os
import pathlib
import tomllib

KNOWN_TOP = {"blend", "mesh", "mesh_up", "object", "colmap", "up", "out", "overwrite",
             "uv_on_copy", "basis", "settings", "photo"}
KNOWN_PHOTO = {"image", "camera", "light", "irradiance", "mask", "sun", "probe", "color_space",
               "exposure", "grey_card", "reference_region", "silhouette_margin"}
KNOWN_SUN = {"date", "utc_offset", "latitude", "longitude", "north_offset"}
KNOWN_PROBE = {"image", "center", "radius"}
# mesh files are imported with their coordinates kept (a photogrammetry mesh shares
# its cameras' frame); mesh_up = "Y" converts a Y-up file to Blender's Z-up instead
MESH_AXES = {"Z": {"forward_axis": "Y", "up_axis": "Z"},
             "Y": {"forward_axis": "NEGATIVE_Z", "up_axis": "Y"}}
# the panel settings (``scene.brdf``) a job's [settings] table may hold, same names
SETTING_NAMES = (
    "use_curvature", "curvature_threshold", "use_monotonicity", "monotonicity_tolerance",
    "use_brightest", "peak_max_angle", "clip_level", "min_cosine", "samples", "trials",
    "subset_fraction", "min_reliable_samples", "kl_path", "kl_bins", "kl_samples", "seed",
    "preset", "region_mode", "sampler", "keep_highlight_energy", "photo_consistent",
    "refine_to_photos", "pixel_footprint", "texture",
    "texture_size", "uv_map", "material_model", "export_gltf",
)


class JobError(ValueError):
    """A job-file mistake, with one sentence for the user."""


@dataclasses.dataclass
class Job:
    """A parsed job; every path is absolute."""

    path: pathlib.Path
    out: pathlib.Path
    blend: pathlib.Path | None = None
    mesh: pathlib.Path | None = None
    object: str | None = None
    colmap: pathlib.Path | None = None
    mesh_up: str = "Z"
    up: list | str | None = None
    overwrite: bool = False
    uv_on_copy: bool = False  # a scan without a UV map: make one on a copy, run on the copy
    basis: tuple[str, pathlib.Path | None] | None = None  # (kind, folder); None: preferences
    settings: dict = dataclasses.field(default_factory=dict)
    photos: list = dataclasses.field(default_factory=list)


def _file(base: pathlib.Path, value, what: str, must_exist: bool = True) -> pathlib.Path:
    if not isinstance(value, str) or not value:
        raise JobError(f"{what} must be a path string")
    path = (base / value).resolve()
    if must_exist and not path.exists():
        raise JobError(f"{what} not found: {path}")
    return path


def load(path) -> Job:
    """Parse and check a job file; JobError (one sentence) on any mistake."""
    path = pathlib.Path(path).resolve()
    if not path.is_file():
        raise JobError(f"job file not found: {path}")
    try:
        # utf-8-sig: a byte-order mark (as some Windows editors write) is not TOML
        data = tomllib.loads(path.read_text(encoding="utf-8-sig"))
    except (tomllib.TOMLDecodeError, UnicodeDecodeError) as error:
        raise JobError(f"job file {path.name} is not valid TOML: {error}") from None
    unknown = set(data) - KNOWN_TOP
    if unknown:
        raise JobError(f"job file has unknown keys: {', '.join(sorted(unknown))}")
    base = path.parent
    job = Job(path=path, out=_file(base, data.get("out", "out"), "out", must_exist=False))
    for folder in (job.out, *job.out.parents):  # the nearest existing one must be a folder
        if folder.exists():
            if not folder.is_dir():
                raise JobError(f"out {job.out} is a file or lies below the file {folder}: "
                               "choose a folder")
            break
    for key in ("overwrite", "uv_on_copy"):
        if key in data:
            if not isinstance(data[key], bool):
                raise JobError(f"{key} must be true or false, got {data[key]!r}")
            setattr(job, key, data[key])
    if "basis" in data:
        job.basis = _basis(base, data["basis"])
    if "blend" in data:
        job.blend = _file(base, data["blend"], "blend")
        if job.blend == job.out / "scene.blend":
            raise JobError(f"out {job.out} would replace the job's own {job.blend.name}: "
                           "choose another out folder")
        _check_input(job.blend, "blend")
    if "mesh" in data and "object" in data:
        raise JobError("give either mesh or object, not both")
    if "mesh" in data:
        job.mesh = _file(base, data["mesh"], "mesh")
        if job.mesh.suffix.lower() not in (".ply", ".obj", ".stl"):
            raise JobError(f"mesh must be .ply, .obj or .stl, got {job.mesh.name}")
        _check_input(job.mesh, "mesh")
    elif "object" in data:
        job.object = str(data["object"])
    else:
        raise JobError("the job needs a mesh file or an object name")
    if "colmap" in data:
        job.colmap = _file(base, data["colmap"], "colmap")
    job.mesh_up = str(data.get("mesh_up", "Z")).upper()
    if job.mesh_up not in MESH_AXES:
        raise JobError(f"mesh_up must be \"Z\" (kept as is) or \"Y\", got {data['mesh_up']!r}")
    if "up" in data:
        up = data["up"]
        if up != "cameras" and not (isinstance(up, list) and len(up) == 3
                                    and all(isinstance(x, int | float) for x in up)):
            raise JobError("up must be [x, y, z] or \"cameras\"")
        job.up = up
    if not isinstance(data.get("settings", {}), dict):
        raise JobError("[settings] must be a table of name = value lines")
    job.settings = dict(data.get("settings", {}))
    unknown = set(job.settings) - set(SETTING_NAMES)
    if unknown:
        raise JobError(f"unknown settings: {', '.join(sorted(unknown))}")
    photos = data.get("photo", [])
    if not photos:
        raise JobError("the job has no [[photo]] entries")
    if not isinstance(photos, list) or not all(isinstance(e, dict) for e in photos):
        raise JobError("photos must be [[photo]] tables (image = \"...\" lines under each), "
                       "not a list of file names")
    for i, entry in enumerate(photos):
        unknown = set(entry) - KNOWN_PHOTO
        if unknown:
            raise JobError(f"photo {i + 1} has unknown keys: {', '.join(sorted(unknown))}")
        if "image" not in entry:
            if "camera" in entry:
                raise JobError(f"camera {entry['camera']} has no photo: give photo {i + 1} "
                               "an image")
            raise JobError(f"photo {i + 1} needs an image")
        camera = entry.get("camera")
        if camera is not None and not (isinstance(camera, str) and camera.strip()):
            raise JobError(f"photo {i + 1}: camera must be a camera's name or its image "
                           f"name, got {camera!r}")
        photo = dict(entry)
        for kind in ("sun", "probe"):  # a [photo.sun] or [photo.probe] table is the light
            if kind in photo:
                if "light" in photo:
                    raise JobError(f"photo {i + 1} has both light and [photo.{kind}]")
                photo["light"] = {kind: photo.pop(kind)}
        photo["image"] = _file(base, entry["image"], f"photo {i + 1} image")
        twin = next((j for j, p in enumerate(job.photos)
                     if os.path.samefile(p["image"], photo["image"])), None)
        if twin is not None:  # one photo counted twice, and the judge's held-out test
            # would predict it from itself
            raise JobError(f"photo {i + 1} is photo {twin + 1} again "
                           f"({photo['image'].name}): list each photo once")
        for key in ("mask", "grey_card", "reference_region"):
            if key in entry:
                photo[key] = _file(base, entry[key], f"photo {i + 1} {key.replace('_', ' ')}")
        if "grey_card" in entry and "reference_region" in entry:
            raise JobError(f"photo {i + 1} has both grey_card and reference_region")
        space = str(entry.get("color_space", "auto")).upper()
        if space not in ("AUTO", "SRGB", "LINEAR"):
            raise JobError(f"photo {i + 1}: color_space must be auto, srgb or linear")
        photo["color_space"] = space
        margin = entry.get("silhouette_margin", 0)
        if not (isinstance(margin, int) and margin >= 0):
            raise JobError(f"photo {i + 1}: silhouette_margin must be a whole number of pixels")
        if "exposure" in entry and not _positive_finite(entry["exposure"]):
            raise JobError(f"photo {i + 1}: exposure must be a positive finite number, "
                           f"got {entry['exposure']!r}")
        if "irradiance" in entry:
            _check_irradiance(i, entry["irradiance"])
        if isinstance(photo.get("light"), dict):
            _check_light_table(i, photo["light"])
        light = photo.get("light")
        if isinstance(light, dict) and "probe" in light:
            light = dict(light)
            light["probe"] = dict(light["probe"])
            light["probe"]["image"] = _file(base, light["probe"].get("image", ""),
                                            f"photo {i + 1} probe image")
            photo["light"] = light
        job.photos.append(photo)
    return job


def _check_input(path: pathlib.Path, field: str) -> None:
    """JobError (one sentence) when the job's ``blend`` or ``mesh`` file cannot be
    what it claims: empty, another format, a truncated PLY, a mesh without faces
    (``core.capture.input_files``). Checked in :func:`load`, before any work:
    Blender would otherwise stop with a traceback, or import nothing."""
    from ..core.capture import input_files

    check = input_files.check_blend if field == "blend" else input_files.check_mesh
    try:
        check(path, field)
    except ValueError as error:
        raise JobError(str(error)) from None


def _basis(base: pathlib.Path, value) -> tuple[str, pathlib.Path | None]:
    """The job's ``basis``: "analytic", "measured" or a folder of MERL ``.binary``
    files (relative to the job file), checked now."""
    if value in ("analytic", "measured"):
        return value.upper(), None
    if not isinstance(value, str) or not value:
        raise JobError(f'basis must be "analytic", "measured" or a folder of MERL .binary '
                       f"files, got {value!r}")
    folder = (base / value).resolve()
    if not folder.is_dir():
        raise JobError(f'basis {value}: not "analytic" or "measured", and no such folder '
                       f"{folder}")
    if not any(folder.glob("*.binary")):
        raise JobError(f"basis folder {folder} holds no MERL .binary files")
    return "FOLDER", folder


def _positive_finite(value) -> bool:
    return (isinstance(value, int | float) and not isinstance(value, bool)
            and math.isfinite(value) and value > 0)


def _check_irradiance(i: int, value) -> None:
    """JobError unless photo i's irradiance is a positive finite number or three of
    them (W/m^2, or relative): 0, negative, Inf or NaN would turn every BRDF value
    into nonsense without a word."""
    values = value if isinstance(value, list) else [value]
    if len(values) not in (1, 3) or (isinstance(value, list) and len(values) != 3):
        raise JobError(f"photo {i + 1}: irradiance must be one number or [r, g, b], "
                       f"got {value!r}")
    if not all(_positive_finite(v) for v in values):
        raise JobError(f"photo {i + 1}: irradiance must be positive and finite, got {value!r}")


def _check_setting(settings, key: str, value, what: str | None = None) -> None:
    """JobError unless ``value`` fits property ``key`` of ``settings`` as it is: the
    right type, finite, inside the property's range, one of its choices. Blender
    would otherwise clamp it silently (samples = -3 running with 1).

    settings: ``scene.brdf``, or anything with its ``bl_rna`` (the ``BRDFPhoto``
        class, for a [photo.sun] table's numbers).
    value: as the job gives it; an ``ANGLE`` property holds radians, the job
        degrees, so its range is compared (and named) in degrees.
    what: how the message names the value (default ``setting <key>``).
    """
    prop = settings.bl_rna.properties[key]
    what = f"setting {key}" if what is None else what
    if prop.type == "BOOLEAN":
        if not isinstance(value, bool):
            raise JobError(f"{what} = {value!r}: must be true or false")
        return
    if prop.type == "ENUM":
        choices = [item.identifier for item in prop.enum_items]
        if value not in choices:
            raise JobError(f"{what} = {value!r}: must be one of {', '.join(choices)}")
        return
    if prop.type in ("INT", "FLOAT"):
        number = int | float if prop.type == "FLOAT" else int
        if isinstance(value, bool) or not isinstance(value, number):
            kind = "a whole number" if prop.type == "INT" else "a number"
            raise JobError(f"{what} = {value!r}: must be {kind}")
        if not math.isfinite(value):
            raise JobError(f"{what} = {value!r}: must be finite")
        low, high, unit = prop.hard_min, prop.hard_max, ""
        if prop.subtype == "ANGLE":  # the job's degrees against the range in degrees
            low, high, unit = math.degrees(low), math.degrees(high), " degrees"
        if not low <= value <= high:
            bounded = prop.hard_max < (2**31 - 1 if prop.type == "INT" else 1e30)
            span = f"from {low:g} to {high:g}" if bounded else f"at least {low:g}"
            raise JobError(f"{what} = {value!r}: must be {span}{unit}")


def _check_light_table(i: int, light: dict) -> None:
    """JobError (one sentence) for a [photo.sun] or [photo.probe] table of photo i
    with unknown keys or half of a pair."""
    for kind, known in (("sun", KNOWN_SUN), ("probe", KNOWN_PROBE)):
        table = light.get(kind)
        if table is None:
            continue
        if set(table) - known:
            raise JobError(f"photo {i + 1} [photo.{kind}] has unknown keys: "
                           + ", ".join(sorted(set(table) - known)))
    sun = light.get("sun", {})
    if ("latitude" in sun) != ("longitude" in sun):
        raise JobError(f"photo {i + 1}: [photo.sun] needs both latitude and longitude "
                       "(or neither, to take them from GPS EXIF)")
    probe = light.get("probe", {})
    if ("center" in probe) != ("radius" in probe):
        raise JobError(f"photo {i + 1}: [photo.probe] needs both center and radius "
                       "(or neither, to find the sphere automatically)")
    if "center" in probe:
        center, radius = probe["center"], probe["radius"]
        if not (isinstance(center, list) and len(center) == 2
                and all(isinstance(x, int | float) for x in center)
                and isinstance(radius, int | float) and radius > 0):
            raise JobError(f"photo {i + 1}: probe center must be [x, y] and radius a "
                           "positive number of pixels")


def apply(job: Job, scene) -> None:
    """Fill ``scene`` from the job: mesh, cameras, settings, photos and lights.

    The settings and a [photo.sun] table's numbers are checked against the panel's
    types and ranges before anything is imported (JobError, one sentence). Angles
    (``peak_max_angle``, ``north_offset``) are degrees in the job and radians in
    ``scene.brdf``. The preset is set first, then the job's other settings over it:
    as in the panel, the preset becomes Custom when one of its values is set to
    another value than the preset's (``preset = "FAST"`` with ``trials = 5`` is
    Custom; with ``trials = 4``, Fast's own value, it stays Fast; ``trials = 16``
    alone keeps the default Balanced, whose value it is).
    """
    import bpy

    from . import colmap_import
    from .props import BRDFPhoto

    settings = scene.brdf
    for key, value in job.settings.items():
        _check_setting(settings, key, value)
    for i, entry in enumerate(job.photos):
        light = entry.get("light")
        sun = light.get("sun") if isinstance(light, dict) else None
        for key in ("utc_offset", "latitude", "longitude", "north_offset"):
            if isinstance(sun, dict) and key in sun:
                _check_setting(BRDFPhoto, key, sun[key], f"photo {i + 1}: [photo.sun] {key}")

    if job.mesh is not None:
        before = set(bpy.data.objects)
        importer = {".ply": bpy.ops.wm.ply_import, ".obj": bpy.ops.wm.obj_import,
                    ".stl": bpy.ops.wm.stl_import}[job.mesh.suffix.lower()]
        try:
            importer(filepath=str(job.mesh), **MESH_AXES[job.mesh_up])
        except RuntimeError as error:  # the importer's own report: a file load() passed
            reason = str(error).strip().splitlines()[-1].removeprefix("Error:").strip()
            raise JobError(f"mesh {job.mesh.name} could not be imported ({reason}): "
                           "export the scan again") from None
        new = [o for o in bpy.data.objects if o not in before and o.type == "MESH"]
        if len(new) != 1:
            raise JobError(f"mesh {job.mesh.name} holds {len(new)} mesh objects, not one")
        target = new[0]
    else:
        target = scene.objects.get(job.object)
        if target is None or target.type != "MESH":
            raise JobError(f"no mesh object named {job.object} in the scene")
    if job.uv_on_copy and not len(target.data.uv_layers):
        from . import uv_copy

        try:
            target = uv_copy.make_uv_copy(scene, target)
        except ValueError as error:
            raise JobError(str(error)) from None
        settings.uv_map = uv_copy.UV_NAME
    settings.target = target
    if job.colmap is not None:
        colmap_import.import_cameras(scene, str(job.colmap))
    if job.up == "cameras":
        from . import light_sources

        settings.scene_up = light_sources.up_from_cameras(scene)[0].tolist()
    elif job.up is not None:
        settings.scene_up = tuple(float(x) for x in job.up)
    # the preset first, then the job's own values over it: one that differs from the
    # preset's makes it Custom (the update callbacks of brdf_addon.props)
    order = sorted(job.settings.items(), key=lambda kv: kv[0] != "preset")
    for key, value in order:
        stored = value
        if settings.bl_rna.properties[key].subtype == "ANGLE":
            stored = math.radians(value)  # the job's degrees; checked above
        try:
            setattr(settings, key, stored)
        except (TypeError, ValueError) as error:
            raise JobError(f"setting {key} = {value!r}: {error}") from None
    settings.output_dir = str(job.out)
    settings.overwrite = job.overwrite
    if job.basis is not None:
        settings.basis = job.basis[0]
        settings.basis_folder = str(job.basis[1] or "")
    for i, entry in enumerate(job.photos):
        try:
            camera = _camera(scene, entry.get("camera"), entry["image"].name)
        except ValueError as error:
            raise JobError(f"photo {i + 1}: {error}") from None
        photo = settings.photos.add()
        photo.name = entry["image"].name
        photo.filepath = str(entry["image"])
        photo.camera = camera
        photo.color_space = entry["color_space"]
        photo.exposure = float(entry.get("exposure", 0.0))
        photo.silhouette_margin = int(entry.get("silhouette_margin", 0))
        if "mask" in entry:
            photo.mask_path = str(entry["mask"])
        for key, kind in (("grey_card", "CARD"), ("reference_region", "SCAN")):
            if key in entry:
                photo.reference_kind, photo.reference_mask_path = kind, str(entry[key])
        if "irradiance" in entry:
            e = entry["irradiance"]
            photo.irradiance = (e, e, e) if isinstance(e, int | float) else tuple(e)
        _set_light(scene, photo, entry.get("light"), i)


def _camera(scene, name: str | None, image_name: str):
    """A camera by object name, else by COLMAP image name (exact, then stem); with
    no name, the camera matching the photo's own file name."""
    from .photo_list import match_camera

    if name is None:
        try:
            return match_camera(scene, image_name)
        except ValueError as error:
            raise ValueError(f"{error}; give its camera") from None
    obj = scene.objects.get(name)
    if obj is not None and obj.type == "CAMERA":
        return obj
    try:
        return match_camera(scene, name)
    except ValueError:
        raise ValueError(f"unknown camera name {name}") from None


def _set_light(scene, photo, light, i: int) -> None:
    if light is None:
        suns = [o for o in scene.objects if o.type == "LIGHT" and o.data.type == "SUN"]
        if len(suns) != 1:
            raise JobError(f"photo {i + 1} has no light (and the scene has {len(suns)} Suns)")
        photo.light_source, photo.sun = "SUN_OBJECT", suns[0]
    elif isinstance(light, str):
        obj = scene.objects.get(light)
        if obj is None or obj.type != "LIGHT" or obj.data.type != "SUN":
            raise JobError(f"photo {i + 1}: no Sun object named {light}")
        photo.light_source, photo.sun = "SUN_OBJECT", obj
    elif isinstance(light, list):
        if len(light) != 3 or not all(isinstance(x, int | float) and not isinstance(x, bool)
                                      for x in light):
            raise JobError(f"photo {i + 1}: light must be three numbers [x, y, z] (the "
                           f"world direction towards the light), got {light!r}")
        if not all(math.isfinite(x) for x in light) or not any(x != 0 for x in light):
            raise JobError(f"photo {i + 1}: light [x, y, z] must be finite and not all zero, "
                           f"got {light!r}")
        photo.light_source, photo.direction = "DIRECTION", tuple(float(x) for x in light)
    elif isinstance(light, dict) and "sun" in light:
        # date, latitude and longitude left out: from the photo's EXIF and GPS
        sun = light["sun"]
        photo.light_source = "SUN_POSITION"
        photo.time_from_exif = "date" not in sun
        if "date" in sun:
            photo.when = str(sun["date"])
        if "utc_offset" in sun:
            photo.utc_offset = float(sun["utc_offset"])
        photo.place_from_exif = "latitude" not in sun  # load() checked they come in pairs
        if not photo.place_from_exif:
            photo.latitude, photo.longitude = float(sun["latitude"]), float(sun["longitude"])
        # degrees in the job (checked by apply), radians in the property
        photo.north_offset = math.radians(float(sun.get("north_offset", 0.0)))
    elif isinstance(light, dict) and "probe" in light:
        probe = light["probe"]
        photo.light_source = "PROBE"
        photo.probe_path = str(probe["image"])
        if "center" in probe:  # load() checked center and radius
            photo.probe_center = tuple(map(float, probe["center"]))
            photo.probe_radius = float(probe["radius"])
    else:
        raise JobError(f"photo {i + 1}: light must be [x, y, z], a Sun name, "
                       "a sun table or a probe table")
