"""The run's inputs, gathered from the scene (main thread, bpy).

:func:`check_scene` validates the scene before any work; :func:`gather` reads
each photo as its camera produced it (``brdf_addon/photo_input.py``: colour
space, saturation, size, lens distortion, exposure, irradiance reference), finds
its light and renders its G-buffers with Cycles (``brdf_addon/gbuffer.py``),
returning ``core.method.pipeline.PhotoInput`` arrays; :func:`capture_notes` says
in words what was done to the photos. Photos and masks are only read.
"""

from __future__ import annotations

import os

import bpy
import numpy as np

from ..core import files
from ..core.method import pipeline
from . import gbuffer, photo_input


def region_labels(obj, mode: str = "MATERIAL_SLOT") -> dict[int, str]:
    """Region id -> a readable name (the material slot's material, or "slot N";
    "face set N")."""
    if mode == "FACE_SET":
        attribute = obj.data.attributes.get(gbuffer.FACE_SET_ATTRIBUTE) if obj else None
        if attribute is None:
            return {0: obj.name if obj is not None else "region 0"}
        ids = np.zeros(len(attribute.data), dtype=np.int32)
        attribute.data.foreach_get("value", ids)
        return {int(i): f"face set {int(i)}" for i in np.unique(ids)}
    if obj is None or not obj.material_slots:
        return {0: obj.name if obj is not None else "region 0"}
    return {i: (slot.material.name if slot.material else f"slot {i}")
            for i, slot in enumerate(obj.material_slots)}


def check_scene(scene) -> None:
    """One-sentence ValueError for what would stop a run before it starts."""
    settings = scene.brdf
    obj = settings.target
    if obj is None:
        raise ValueError("choose the scan object (a mesh) in the BRDF panel")
    if obj.type != "MESH" or len(obj.data.polygons) == 0:
        raise ValueError(f"the scan {obj.name} is a mesh without faces")
    _check_scan_geometry(obj)
    if settings.texture:
        from . import gbuffer

        gbuffer.check_uv_map(obj, settings.uv_map)
    if not len(settings.photos):
        raise ValueError("add at least one lit photo")
    for photo in settings.photos:
        if not photo.filepath:
            if photo.camera is not None:
                raise ValueError(f"camera {photo.camera.name} has no photo: choose the "
                                 f"image file of entry {photo.name or '(unnamed)'}")
            raise ValueError(f"photo {photo.name} has no image file")
        if not os.path.isfile(bpy.path.abspath(photo.filepath)):
            raise ValueError(f"photo file not found: {bpy.path.abspath(photo.filepath)}")
        if photo.camera is None:
            raise ValueError(f"photo {photo.name} has no camera: pick the camera it was "
                             "taken from")
    _check_output_folder(scene)


def _check_scan_geometry(obj) -> None:
    """One-sentence ValueError for a scan no photo can see as a surface: vertices with
    NaN or Inf coordinates (a broken export; Cycles drops their faces silently), no
    face with an area (every face collapsed to a line or a point), or a transform
    that is not finite or scales the scan to nothing. The mesh is only read."""
    mesh = obj.data
    co = np.empty(3 * len(mesh.vertices), dtype=np.float64)
    mesh.vertices.foreach_get("co", co)
    bad = int(np.count_nonzero(~np.all(np.isfinite(co.reshape(-1, 3)), axis=1)))
    if bad:
        raise ValueError(f"the scan {obj.name} has {bad} vertex{'es' if bad > 1 else ''} "
                         "with NaN or Inf coordinates: fix or delete them, or export the "
                         "scan again")
    area = np.empty(len(mesh.polygons), dtype=np.float64)
    mesh.polygons.foreach_get("area", area)
    if not np.any(area > 0.0):
        raise ValueError(f"the scan {obj.name} has no face with an area (every face is "
                         "collapsed to a line or a point)")
    matrix = np.array(obj.matrix_world, dtype=np.float64)
    if not np.all(np.isfinite(matrix)) or abs(np.linalg.det(matrix[:3, :3])) == 0.0:
        raise ValueError(f"the scan {obj.name}'s transform scales it to nothing or is not "
                         "finite: check its scale in the Object properties")


def _check_output_folder(scene) -> None:
    """ValueError when the output folder is a file, or holds files of the run's names
    that no run wrote, unless the user asked to overwrite them."""
    from . import outputs

    out = outputs.output_path(scene)
    if out.exists() and not out.is_dir():
        raise ValueError(f"the output folder {out} is a file: choose a folder")
    existing = next(p for p in (out, *out.parents) if p.exists())
    if not existing.is_dir():
        raise ValueError(f"the output folder {out} lies below the file {existing}: "
                         "choose a folder")
    if not os.access(existing, os.W_OK | os.X_OK):
        raise ValueError(f"the output folder {out} cannot be written ({existing} is not "
                         "writable for you): choose another folder")
    replaced = files.files_a_run_would_replace(out)
    if replaced and not scene.brdf.overwrite:
        shown = ", ".join(replaced[:4]) + (f" and {len(replaced) - 4} more"
                                           if len(replaced) > 4 else "")
        raise ValueError(f"the output folder {out} holds {shown}, which this run would "
                         "replace; choose another folder or turn on Overwrite "
                         "(overwrite = true in a job)")


def gather(scene) -> list[pipeline.PhotoInput]:
    """Photos, lights and Cycles G-buffers for every photo of ``scene.brdf`` at once
    (:class:`runner.Run` does the same one photo per step). Raises
    ValueError (one sentence) for a bad scene."""
    return gather_capture(scene)[0]


def gather_capture(scene) -> tuple[list[pipeline.PhotoInput], dict]:
    """:func:`gather`, and what was applied to the photos (the report's ``capture``)."""
    check_scene(scene)
    scales, notes = photo_input.exposure_plan(scene)
    gathered = [photo_input.gather_photo(scene, photo, float(k), note)
                for photo, k, note in zip(scene.brdf.photos, scales, notes, strict=True)]
    return capture_inputs(gathered)


def capture_inputs(gathered) -> tuple[list[pipeline.PhotoInput], dict]:
    """Pipeline inputs of gathered photos (irradiance references applied) and the
    report's ``capture`` section."""
    inputs, irradiance_notes = photo_input.apply_irradiance(gathered)
    return inputs, {"photos": [g.report for g in gathered], "irradiance": irradiance_notes}


def capture_notes(capture: dict) -> list[str]:
    """One line per thing done to the photos that the user should know: a scaled,
    partial (an EXR's data window smaller than its frame), multilayer or undistorted
    photo, an exposure scale, saturated pixels (left out) and the ones clipped at the
    file's own white level (used), the irradiance rule,
    and each photo's warnings (its ``notes``: a photo partly inconsistent with its light,
    ``core.capture.photo_checks``)."""
    lines = []
    photos = capture.get("photos", [])
    for p in photos:
        name = p.get("name", "")
        if p.get("scaled"):
            lines.append(f"{name}: {p['scaled']}")
        if p.get("partial"):
            lines.append(f"{name}: {p['partial']}")
        if p.get("layer"):
            lines.append(f"{name}: colour read from its layer {p['layer']}")
        if p.get("undistorted"):
            lines.append(f"{name}: undistorted ({p['undistorted']})")
        if p.get("exposure") and p.get("exposure_scale", 1.0) != 1.0:
            lines.append(p["exposure"])
        if p.get("saturated_pixels"):
            lines.append(f"{name}: {p['saturated_pixels']} saturated pixels excluded")
        if p.get("clipped_pixels"):
            lines.append(
                f"{name}: {p['clipped_pixels']} pixels on the scan are at "
                f"{p['white_level']}, a highlight "
                "clipped at the camera's white level: its peak is not in the photo (a "
                "shorter exposure or a merged bracket would hold it); they are used at that "
                "value (a Saturation Level at or below it leaves them out)")
        uncertainty = p.get("light", {}).get("uncertainty_deg")
        if uncertainty is not None:
            lines.append(f"{name}: sphere-probe light, uncertainty {uncertainty:.2f} deg")
        lines.extend(f"{name}: {note}" for note in p.get("notes", []))
    if len(photos) > 1 and all("assumed equally exposed" in p.get("exposure", "")
                               for p in photos):
        lines.append("no exposure EXIF: photos assumed equally exposed")
    return lines + list(capture.get("irradiance", []))
