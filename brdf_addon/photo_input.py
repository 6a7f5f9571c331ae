"""A lit photo as a camera produced it, made ready for ``core.method.pipeline`` (bpy glue).

For each entry of ``scene.brdf.photos`` :func:`gather_photo`:

1. reads the file as linear radiance (``core.capture.photo_io``: EXR and 16/32-bit TIFF
   linear, 8/16-bit PNG and JPEG sRGB unless the file or the user says linear,
   camera RAW only where OpenImageIO has LibRaw), the pixels clipped at the file's
   own white level (an integer file's largest code, a float file's plateau: used
   at their value and reported) and the saturated ones (at or above the Saturation
   Level setting, on the file's own values: left out);
2. checks the photo's size against its camera's: the same, or the same aspect
   ratio scaled (said in the report); anything else is an error, and so is a
   photo under 4 pixels a side (``core.capture.photo_checks``);
3. reads the mask image; refuses NaN or Inf inside it and a black photo, one
   sentence each (``photo_checks``);
4. undistorts photo, masks and saturation through the COLMAP camera model
   (``core.capture.undistort``) when the camera has lens distortion, so the pixels line
   up with the Blender (pinhole) camera;
5. finds the light (``light_sources.photo_light``) and renders the G-buffers
   (with Pixel Footprint where a refit reads it, also the scan's normals at 2 x 2
   points of each pixel, ``core.method.gbuffers.footprint_normals``);
   the scan's silhouette is the mask, shrunk by the photo's silhouette margin;
   refuses a photo black over the scan, one with values no camera records there
   (more than 2^32 times the median of the scan's pixels), or one brighter where
   the G-buffer says shadow than where it says light, and notes one that is partly so
   (``photo_checks.light_consistency``) or holds values below 0 on the scan beyond
   a black level's noise (``photo_checks.negative_note``; the photo's ``notes``);
6. applies the exposure scale (user, or EXIF shutter/aperture/ISO through
   ``core.capture.exif``; :func:`exposure_plan` decides for all photos at once);
7. gathers the irradiance reference (grey card or diffuse region of the scan),
   which :func:`apply_irradiance` turns into per-photo irradiance ratios
   (``core.capture.irradiance``).

Every step says what it applied in the photo's ``report`` dict, which goes to
``report.json`` as ``capture`` (warnings in its ``notes``, which
``gathering.capture_notes`` prints and the panel shows). Nothing of the user's
is changed: files are only read.
"""

from __future__ import annotations

import dataclasses

import bpy
import numpy as np
from scipy import ndimage

from ..core.capture import exif, irradiance, photo_checks, photo_io, undistort
from ..core.method import gbuffers, pipeline
from . import gbuffer, light_sources, prefs, props

# With the Pixel Footprint setting, the scan's normals are also rendered at this many
# times the photo's width and height: 2 x 2 points per pixel, whose mean radiance the
# refits to every pixel predict (a pixel records the light over its area).
FOOTPRINT_FACTOR = 2


@dataclasses.dataclass
class GatheredPhoto:
    """One photo made ready: the pipeline's input, what was applied (JSON-friendly),
    and its irradiance reference (None without one)."""

    input: pipeline.PhotoInput
    report: dict
    reference: irradiance.Reference | None = None


def exposure_plan(scene) -> tuple[np.ndarray, list[str]]:
    """(N,) exposure scales of ``scene.brdf.photos`` onto the first photo's scale,
    and one note per photo. A photo's own Exposure Scale (> 0) wins over its EXIF;
    ValueError (one sentence) when EXIF is present on some photos and missing on
    others that have no scale of their own."""
    photos = list(scene.brdf.photos)
    exposures = [exif.exposure_settings(photo_io.read_metadata(bpy.path.abspath(p.filepath)))
                 for p in photos]
    user = [p.exposure if p.exposure > 0 else None for p in photos]
    return exif.exposure_scales(exposures, user, names=[p.name for p in photos])


def check_size(name: str, camera_name: str, photo_size, want, source: str) -> str:
    """'' when the photo is its camera's size, a note when it is the same aspect
    ratio scaled; ValueError (one sentence) otherwise, or when the photo is under
    ``photo_checks.MIN_SIDE_PX`` a side. Sizes are (width, height) in pixels."""
    photo_checks.check_photo_size(name, photo_size, camera_name, want, source)
    (w, h), (cw, ch) = photo_size, want
    if (w, h) == (cw, ch):
        return ""
    if abs(h - ch * w / cw) < 1.0 and abs(w - cw * h / ch) < 1.0:
        return (f"{w}x{h} pixels, {w / cw:.4g} times its camera's {cw}x{ch}: the camera "
                "is scaled to the photo")
    raise ValueError(f"photo {name} is {w}x{h} pixels but its camera {camera_name} is "
                     f"{cw}x{ch} ({source}), a different aspect ratio")


def white_level(read: photo_io.Photo) -> str:
    """The file's own white level in words: an integer file's largest code, or a float
    file's plateau per channel (``photo_io.Photo.plateau``)."""
    if read.plateau is None:
        return "the file's largest code"
    levels = ", ".join(f"{name} {level:.6g}" for name, level in zip(
        ("red", "green", "blue"), read.plateau, strict=True) if np.isfinite(level))
    return f"the file's largest value, where its brightest pixels pile up ({levels})"


def gather_photo(scene, photo, exposure_scale: float = 1.0,
                 exposure_note: str = "") -> GatheredPhoto:
    """One photo: read, checked, undistorted, lit, G-buffers, exposure, reference.
    Raises ValueError (one sentence) for a bad photo."""
    settings = scene.brdf
    path = bpy.path.abspath(photo.filepath)
    # pixels at the file's own white level (an integer file's largest code; a float
    # file's plateau, looked for unless the user gave the level) are used at their value
    # and said; only the user's Saturation Level leaves pixels out: on a blunted scan
    # the clipped pixels used give the better table (bench/clipping_bench.py)
    read = photo_io.read_photo_file(path, photo.color_space,
                                    find_clipping=settings.clip_level <= 0)
    radiance, clipped = read.radiance, read.saturated
    saturated = np.zeros_like(clipped)
    h, w = radiance.shape[:2]
    want, source = gbuffer.camera_resolution(photo.camera, scene)
    want = (int(want[0]), int(want[1]))
    note = check_size(photo.name, photo.camera.name, (w, h), want, source)
    report = {"name": photo.name, "file": path, "format": read.file_format,
              "bit_depth": read.bit_depth, "encoding": read.encoding,
              "encoding_reason": read.encoding_reason}
    mask = None
    if photo.mask_path:
        mask = photo_io.read_mask(bpy.path.abspath(photo.mask_path), (h, w))
    if read.layer is not None:  # a multilayer file: its colour layer, by name
        report["layer"] = read.layer
    if read.covered is not None:  # the file holds part of its frame: only that is used
        mask = read.covered if mask is None else mask & read.covered
        report["partial"] = (f"the file holds {np.count_nonzero(read.covered)} of the "
                             f"frame's {w * h} pixels (its data window); only those are "
                             "used")
    photo_io.check_finite(radiance, photo.name, mask)
    photo_checks.check_not_black(radiance, photo.name, mask)
    if settings.clip_level > 0:  # on the file's values, before any scaling
        saturated = saturated | np.any(radiance >= settings.clip_level, axis=-1)
    if note:
        report["scaled"] = note
    reference_mask = None
    if photo.reference_kind != "NONE":
        if not photo.reference_mask_path:
            raise ValueError(f"photo {photo.name} has an irradiance reference but no "
                             "reference mask")
        reference_mask = photo_io.read_mask(bpy.path.abspath(photo.reference_mask_path),
                                            (h, w))
    if photo.camera.get("brdf_colmap_distorted"):
        if "brdf_colmap_params" not in photo.camera:  # imported by an older version
            raise ValueError(f"camera {photo.camera.name} has lens distortion but no stored "
                             "lens parameters; import its COLMAP model again")
        model = str(photo.camera["brdf_colmap_camera_model"])
        params = [float(x) for x in photo.camera["brdf_colmap_params"]]
        args = (model, params, *want)
        radiance = undistort.undistort_image(radiance, *args)
        saturated = undistort.undistort_mask(saturated, *args)
        clipped = undistort.undistort_mask(clipped, *args)
        if mask is not None:
            mask = undistort.undistort_mask(mask, *args)
        if reference_mask is not None:
            reference_mask = undistort.undistort_mask(reference_mask, *args)
        report["undistorted"] = f"{model} {np.round(params, 6).tolist()}"
    light_details = {}
    light = light_sources.photo_light(scene, photo, light_details)
    report["light"] = light_details | {"direction": light.tolist()}
    attribute = ("material_index" if settings.region_mode == "MATERIAL_SLOT"
                 else gbuffer.FACE_SET_ATTRIBUTE)
    g = gbuffer.render_gbuffers(settings.target, photo.camera, light, resolution=(w, h),
                                device=prefs.cycles_device(), region_attribute=attribute,
                                uv=settings.texture, uv_map=settings.uv_map)
    if not g.mask.any():
        raise ValueError(f"the scan is not in view of photo {photo.name}'s camera")
    footprint = None
    if props.footprint_used(settings):  # the scan's normals over each pixel's area
        fine = gbuffer.render_gbuffers(
            settings.target, photo.camera, light,
            resolution=(w * FOOTPRINT_FACTOR, h * FOOTPRINT_FACTOR),
            device=prefs.cycles_device(), region_attribute=attribute)
        footprint = gbuffers.footprint_normals(fine, FOOTPRINT_FACTOR)
        report["pixel_footprint"] = FOOTPRINT_FACTOR * FOOTPRINT_FACTOR
    cosine = np.einsum("hwc,c->hw", g.normal, light)
    if not np.any(cosine[g.mask] > 0):
        raise ValueError(f"the light of photo {photo.name} is below every surface of the scan")
    if photo.silhouette_margin > 0:
        inside = ndimage.binary_erosion(g.mask, iterations=photo.silhouette_margin)
        mask = inside if mask is None else mask & inside
        report["silhouette_margin_px"] = int(photo.silhouette_margin)
    usable = g.mask if mask is None else g.mask & mask  # the scan's pixels the run uses
    photo_checks.check_scan_not_black(radiance, photo.name, usable)
    photo_checks.check_range(radiance, photo.name, usable, where=" on the scan")
    consistency = photo_checks.light_consistency(radiance, cosine, g.visibility, g.region,
                                                 usable)
    report["light_check"] = consistency.as_dict()
    negative = photo_checks.negative_note(radiance, photo.name, usable)
    notes = ([negative] if negative else []) + photo_checks.check_light(consistency,
                                                                        photo.name)
    if notes:
        report["notes"] = notes
    if exposure_scale != 1.0:
        radiance = radiance * exposure_scale
    report["exposure_scale"] = float(exposure_scale)
    if exposure_note:
        report["exposure"] = exposure_note
    report["saturated_pixels"] = int(np.count_nonzero(saturated & g.mask))
    report["clipped_pixels"] = int(np.count_nonzero(clipped & ~saturated & g.mask))
    if report["clipped_pixels"]:
        report["white_level"] = white_level(read)
    reference = None
    if reference_mask is not None:
        if photo.reference_kind == "SCAN":  # n.l of the scan, from its G-buffer
            region = reference_mask & g.mask
            reference = irradiance.Reference(radiance=radiance[region], cosine=cosine[region],
                                             saturated=(saturated | clipped)[region])
        else:  # a grey card facing the light
            region = reference_mask
            reference = irradiance.grey_card(radiance[region], 1.0,
                                             (saturated | clipped)[region])
        report["reference"] = {"kind": photo.reference_kind.lower(),
                               "pixels": int(np.count_nonzero(region))}
    return GatheredPhoto(
        input=pipeline.PhotoInput(
            photo=radiance, normal=g.normal, position=g.position, visibility=g.visibility,
            region=g.region, camera_center=g.camera_center, light=light,
            irradiance=np.array(photo.irradiance, dtype=np.float64), mask=mask,
            name=photo.name, saturated=saturated, uv=g.uv, footprint_normal=footprint),
        report=report, reference=reference)


def apply_irradiance(gathered: list[GatheredPhoto]) -> tuple[list[pipeline.PhotoInput], list]:
    """The pipeline inputs with each photo's irradiance from the references: the
    first photo keeps its own, the others get it times their ratio to it
    (``core.capture.irradiance.relative_irradiance``). Without references the irradiances
    stay as given, and the note says whether that means equal. Returns (inputs,
    notes)."""
    references = [g.reference for g in gathered]
    if all(r is None for r in references):
        given = np.array([np.asarray(g.input.irradiance, dtype=np.float64) for g in gathered])
        if (given == given[0]).all():
            return [g.input for g in gathered], [
                "no gray card or reference region: irradiance assumed equal across photos"]
        return [g.input for g in gathered], ["no gray card or reference region: irradiance "
                                             "as given per photo"]
    ratios, notes = irradiance.relative_irradiance(
        references, names=[g.input.name for g in gathered])
    base = np.asarray(gathered[0].input.irradiance, dtype=np.float64)
    inputs = []
    for g, ratio in zip(gathered, ratios, strict=True):
        e = base * ratio
        if not np.all(np.isfinite(e)) or not np.all(e > 0):
            raise ValueError(f"the irradiance reference of photo {g.input.name} gives no "
                             "usable irradiance (is it dark or saturated?)")
        g.report["irradiance"] = e.tolist()
        inputs.append(dataclasses.replace(g.input, irradiance=e))
    return inputs, notes

