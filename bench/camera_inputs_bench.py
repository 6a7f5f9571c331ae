"""What real-camera inputs cost the reconstruction, end to end through the batch entry.

The demo's capture (``testkit/capture.py``: the degraded bunny scan, the COLMAP ring,
3 linear EXR photos under one distant light, shaded by a held-out table; the
demo's cache, ``capture.cache_folder``) is turned into the photos and job files a
camera and a user would produce, and each is run through
``python -m brdf_reconstruct.brdf_addon.batch job.toml`` in a fresh subprocess
(Balanced preset, seed 0 as ``make demo``, then seeds 1 to 3 with every variant:
the spread of the random-subset trials). The table read back from
``out/brdf_0.binary`` is scored against the capture's ``truth.binary`` with
``core.brdf.metrics.sphere_error`` and ``brdf_log_rmse``. Variants:

- ``exr``: the capture as is, through ``capture.preset_job`` (the demo's job): the
  baseline, which must give the demo's numbers.
- ``tiff16``: 16-bit linear TIFF, one scale s for all photos (manual exposure) so
  that the brightest pixel of the set is 0.9 of full scale; EXIF ExposureTime,
  FNumber and ISO as ``Exif:ISOSpeed`` (OIIO's TIFF writer drops
  ``Exif:ISOSpeedRatings`` / ``PhotographicSensitivity``, keeps ``Exif:ISOSpeed``,
  which ``core.capture.exif`` reads). EXIF only gives scales relative to the first photo
  (``exif.exposure_scales``), so the absolute scale s goes into the job as the
  light's irradiance in the photos' units, ``irradiance = s``.
- ``jpeg8``: 8-bit sRGB JPEG, quality 95, the same scale and handling, ISO as
  ``Exif:ISOSpeedRatings``.
- ``png8``: 8-bit sRGB PNG, the same scale (lossless control for ``jpeg8`` and
  ``clipped``).
- ``exposures``: EXR photos at x1, x0.5 and x2 exposure, ``ExposureTime`` in the
  EXR header (1/125 s times the factor, f/8, ISO 100), normalised by the product
  from EXIF (the first photo, x1, is the reference).
- ``clipped``: 8-bit sRGB PNG exposed so that about 2.5 % of the object's pixels
  (EXR alpha >= 0.5, all photos) hold code 255 in some channel; the product finds
  them at the file's largest code, says so and uses them at their value (since
  2026-12-07; it left them out before). ``irradiance = s``, as above.
- ``distorted_<lens>``: the EXR photos resampled through an OPENCV lens (cubic
  spline of the pinhole photo at the pinhole position of each distorted pixel)
  and the COLMAP model rewritten through pycolmap with that camera model
  (``testkit.synthetic.synthetic_reconstruction``, the poses, intrinsics and points
  of the capture's model), so the product must undistort them; and
  ``distorted_<lens>_ignored``: the same photos with the capture's PINHOLE model
  (a user who ignores the distortion). Lenses: barrel (k1 -0.15, k2 0.02) and
  pincushion (k1 0.1, k2 -0.01), p1 = p2 = 0. Beside the runs: the round trip
  distort -> ``core.capture.undistort.undistort_image`` (order 1, the product's, and
  order 3) against the original photo, the resampling cost alone, and the
  distorted photo against the original (the misalignment a PINHOLE model keeps).

Recorded per variant: the two errors, the report's counts (observed, reliable,
saturated, removed per stage) and the stages its region skipped, the batch
subprocess's wall time, the report's ``capture`` section, and what was written
(scales; EXIF read back through ``core.capture.photo_io.read_metadata`` and
``core.capture.exif.exposure_settings``; the clipped share; for the integer files the
decoded pixels against the EXR: the share of object pixels more than 2x off in the
monotonicity stage's log measure).
Writes ``bench/results/camera_inputs.json`` and ``camera_inputs.png``.

Run::

    BRDF_RECONSTRUCT_CACHE=/work/main/.cache .venv/bin/python bench/camera_inputs_bench.py
    # --materials heldout_gold_medium   (default: the demo's gold and heldout_rough_plastic)

About 13 minutes on 2 cores with both captures cached: 20 variants x 4 seeds, each
batch run about 9 s. The headline numbers are seed 0's; ``over_seeds`` has the
median, min and max over the seeds.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import pathlib
import shutil
import sys
import tempfile
import time
import tomllib

import common
import numpy as np

RESULTS = common.RESULTS
COMMAND = ".venv/bin/python bench/camera_inputs_bench.py"
MATERIALS = ("heldout_gold_medium", "heldout_rough_plastic")
CAPTURE = common.DEMO_CAPTURE
NOTE = "2 shared cores; wall times are indicative (load_1min per run)"
PRESET = "BALANCED"
PEAK = 0.9  # the brightest pixel of the set at this fraction of full scale (tiff16, 8-bit)
CLIP_SHARE = 0.025  # share of the object's pixels with a channel at code 255 (clipped)
BASE_EXPOSURE = {"shutter_s": 1 / 125, "f_number": 8.0, "iso": 100}
EXPOSURE_FACTORS = (1.0, 0.5, 2.0)
LENSES = {"barrel": (-0.15, 0.02), "pincushion": (0.1, -0.01)}


# --------------------------------------------------------------------------- files


def read_exr(path: pathlib.Path) -> tuple[np.ndarray, object]:
    """(H, W, C) float32 pixels and the ImageSpec of an EXR."""
    import OpenImageIO as oiio

    inp = oiio.ImageInput.open(str(path))
    if inp is None:
        raise RuntimeError(oiio.geterror())
    spec = inp.spec()
    pixels = np.asarray(inp.read_image(0, 0, 0, spec.nchannels, oiio.FLOAT))
    inp.close()
    return pixels.reshape(spec.height, spec.width, spec.nchannels).copy(), spec


def write_image(path: pathlib.Path, pixels: np.ndarray, exif: dict | None = None,
                base_spec=None, quality: int | None = None) -> None:
    """Write ``pixels`` (H, W, C) in the dtype's format (float32, uint16, uint8) with
    the EXIF attributes given (name -> value). ``base_spec``: copy its attributes
    (the EXR header) first."""
    import OpenImageIO as oiio

    kind = {np.dtype(np.float32): oiio.FLOAT, np.dtype(np.uint16): oiio.UINT16,
            np.dtype(np.uint8): oiio.UINT8}[pixels.dtype]
    h, w, c = pixels.shape
    spec = oiio.ImageSpec(w, h, c, kind)
    if base_spec is not None:
        spec.channelnames = tuple(base_spec.channelnames)
        for attribute in base_spec.extra_attribs:
            if not attribute.name.startswith("oiio:subimage"):
                spec.attribute(attribute.name, attribute.type, attribute.value)
    for name, value in (exif or {}).items():
        spec.attribute(name, value)
    if quality is not None:
        spec.attribute("Compression", f"jpeg:{quality}")
    out = oiio.ImageOutput.create(str(path))
    if out is None or not out.open(str(path), spec):
        raise RuntimeError(f"cannot write {path}: {oiio.geterror()}")
    out.write_image(np.ascontiguousarray(pixels))
    out.close()


def exif_attributes(factor: float, iso_name: str) -> dict:
    """EXIF exposure of a photo exposed ``factor`` times the base exposure (shutter)."""
    return {"ExposureTime": float(BASE_EXPOSURE["shutter_s"] * factor),
            "FNumber": float(BASE_EXPOSURE["f_number"]), iso_name: int(BASE_EXPOSURE["iso"])}


def linear_to_srgb(x: np.ndarray) -> np.ndarray:
    """IEC 61966-2-1 sRGB encoding of linear values in [0, 1]."""
    x = np.clip(x, 0.0, 1.0)
    return np.where(x <= 0.0031308, 12.92 * x, 1.055 * np.power(x, 1 / 2.4) - 0.055)


def quantise(values: np.ndarray, dtype) -> np.ndarray:
    top = np.iinfo(dtype).max
    return np.round(np.clip(values, 0.0, 1.0) * top).astype(dtype)


def metadata_check(path: pathlib.Path) -> dict:
    """What the product's readers make of a written file's exposure EXIF."""
    from brdf_reconstruct.core.capture import exif, photo_io

    exposure = exif.exposure_settings(photo_io.read_metadata(path))
    return {"file": path.name, "exposure_read_back": exposure.describe() if exposure else None,
            "relative_gain": exposure.relative_gain if exposure else None}


def decoded_vs_exr(path: pathlib.Path, exr_rgb: np.ndarray, obj: np.ndarray,
                   scale: float) -> dict:
    """The written file as the product decodes it (``core.capture.photo_io.read_photo_file``),
    divided by the scale, against the EXR on the object's pixels: the share of pixels
    more than a factor 2 off in some channel, in the monotonicity stage's log measure
    (``ln(x + delta)``, delta = 1e-3 x the channel's median, ``core.method.reliable``), and
    the share decoded as 0 in some channel."""
    from brdf_reconstruct.core.capture import photo_io

    got = photo_io.read_photo_file(path).radiance[obj] / scale
    ref = exr_rgb[obj]
    delta = 1e-3 * np.median(ref, axis=0)
    off = np.abs(np.log((np.maximum(got, 0.0) + delta) / (ref + delta))) > np.log(2.0)
    return {"object_share_off_2x": float(np.mean(np.any(off, axis=1))),
            "object_share_decoded_zero": float(np.mean(np.any(got <= 0.0, axis=1))),
            "object_share_zero_in_exr": float(np.mean(np.any(ref <= 0.0, axis=1)))}


# --------------------------------------------------------------------------- jobs


def write_job(folder: pathlib.Path, capture_dir: pathlib.Path, photos: list[dict],
              colmap_dir: pathlib.Path | None, seed: int) -> tuple[pathlib.Path, pathlib.Path]:
    """A job file ``folder/job_s<seed>.toml`` like the capture's own, Balanced preset,
    the given seed, ``out_s<seed>`` beside it; ``photos``: the [[photo]] entries (image
    relative to ``folder``); ``colmap_dir`` None: the capture's model. Returns (job, out)."""
    base = tomllib.loads((capture_dir / "job.toml").read_text())
    lines = [f'mesh = "{(capture_dir / base["mesh"]).as_posix()}"',
             f'colmap = "{(colmap_dir or capture_dir / base["colmap"]).as_posix()}"',
             f'out = "out_s{seed}"', "", "[settings]", f'preset = "{PRESET}"',
             f"seed = {seed}", ""]
    for entry in photos:
        lines.append("[[photo]]")
        for key, value in entry.items():
            lines.append(f"{key} = {json.dumps(value)}")
        lines.append("")
    job = folder / f"job_s{seed}.toml"
    job.write_text("\n".join(lines))
    return job, folder / f"out_s{seed}"


def photo_entries(capture_dir: pathlib.Path) -> list[dict]:
    """The capture job's [[photo]] entries (image, camera, light)."""
    return tomllib.loads((capture_dir / "job.toml").read_text())["photo"]


# --------------------------------------------------------------------------- variants


@dataclasses.dataclass
class Variant:
    """A variant's files: its folder, the [[photo]] entries of its jobs (images relative
    to the folder), its COLMAP model (None: the capture's) and what was written."""

    name: str
    folder: pathlib.Path
    entries: list[dict]
    colmap_dir: pathlib.Path | None
    info: dict


def integer_variant(work, capture_dir, lit, kind: str) -> Variant:
    """tiff16 / jpeg8 / png8 / clipped: one scale s for all photos, EXIF on every file,
    ``irradiance = s`` in the job."""
    folder = work / kind
    (folder / "lit").mkdir(parents=True)
    rgb = [pixels[..., :3].astype(np.float64) for pixels, _ in lit]
    if kind == "clipped":
        # code 255 where the sRGB value rounds up to it: linear >= decode(254.5 / 255)
        from brdf_reconstruct.core.capture.photo_io import srgb_to_linear

        threshold = float(srgb_to_linear(254.5 / 255.0))
        peaks = np.concatenate([p[..., :3].max(-1)[p[..., 3] >= 0.5] for p, _ in lit])
        scale = threshold / float(np.quantile(peaks, 1.0 - CLIP_SHARE))
    else:
        scale = PEAK / max(float(c.max()) for c in rgb)
    ext, dtype, iso_name, quality = {
        "tiff16": (".tif", np.uint16, "Exif:ISOSpeed", None),
        "jpeg8": (".jpg", np.uint8, "Exif:ISOSpeedRatings", 95),
        "png8": (".png", np.uint8, "Exif:ISOSpeedRatings", None),
        "clipped": (".png", np.uint8, "Exif:ISOSpeedRatings", None)}[kind]
    entries, written, clipped_object, object_pixels = [], [], 0, 0
    for (pixels, _), entry, values in zip(lit, photo_entries(capture_dir), rgb, strict=True):
        linear = values * scale
        encoded = linear if kind == "tiff16" else linear_to_srgb(linear)
        codes = quantise(encoded, dtype)
        path = folder / "lit" / (pathlib.Path(entry["image"]).stem + ext)
        write_image(path, codes, exif_attributes(1.0, iso_name), quality=quality)
        top = np.iinfo(dtype).max
        obj = pixels[..., 3] >= 0.5
        at_top = np.any(codes == top, axis=-1)
        clipped_object += int(np.count_nonzero(at_top & obj))
        object_pixels += int(np.count_nonzero(obj))
        written.append(metadata_check(path) | {
            "max_code": int(codes.max()), "pixels_at_max_code": int(np.count_nonzero(at_top)),
            "object_pixels_at_max_code": int(np.count_nonzero(at_top & obj)),
            **decoded_vs_exr(path, values, obj, scale)})
        entries.append({"image": f"lit/{path.name}", "camera": entry["camera"],
                        "light": entry["light"], "irradiance": scale})
    info = {"scale": scale, "irradiance_in_job": scale,
            "why_irradiance": "EXIF gives exposure relative to the first photo only "
                              "(core.capture.exif.exposure_scales); the absolute scale s of the "
                              "pixel values is the light's irradiance in the photos' units",
            "files": written,
            "object_pixels": object_pixels, "object_pixels_clipped": clipped_object,
            "object_share_clipped": clipped_object / object_pixels}
    return Variant(kind, folder, entries, None, info)


def exposures_variant(work, capture_dir, lit) -> Variant:
    """EXR photos at EXPOSURE_FACTORS, ExposureTime in the header; no scale in the job."""
    folder = work / "exposures"
    (folder / "lit").mkdir(parents=True)
    entries, written = [], []
    for i, ((pixels, spec), entry) in enumerate(zip(lit, photo_entries(capture_dir),
                                                   strict=True)):
        factor = EXPOSURE_FACTORS[i % len(EXPOSURE_FACTORS)]
        scaled = pixels.copy()
        scaled[..., :3] *= np.float32(factor)
        path = folder / "lit" / pathlib.Path(entry["image"]).name
        write_image(path, scaled, exif_attributes(factor, "Exif:ISOSpeedRatings"),
                    base_spec=spec)
        written.append(metadata_check(path) | {"factor": factor})
        entries.append({"image": f"lit/{path.name}", "camera": entry["camera"],
                        "light": entry["light"]})
    # the first photo is the EXIF reference; its factor is the absolute scale left
    irradiance = EXPOSURE_FACTORS[0]
    if irradiance != 1.0:
        for entry in entries:
            entry["irradiance"] = irradiance
    return Variant("exposures", folder, entries, None,
                   {"factors": EXPOSURE_FACTORS[:len(lit)], "files": written})


def distort_photo(pixels: np.ndarray, model_params, width: int, height: int) -> np.ndarray:
    """A pinhole photo as the OPENCV lens would have taken it: each distorted pixel
    takes the cubic spline of the pinhole photo at its undistorted position (0 and
    alpha 0 outside the pinhole view)."""
    from scipy import ndimage

    from brdf_reconstruct.core.capture import colmap

    camera = colmap.pycolmap_camera("OPENCV", model_params, width, height)
    fx, fy, cx, cy = model_params[:4]
    h, w = pixels.shape[:2]
    x, y = np.meshgrid(np.arange(w) + 0.5, np.arange(h) + 0.5)
    normalised = np.asarray(camera.cam_from_img(np.stack([x.ravel(), y.ravel()], axis=1)),
                            dtype=np.float64)[:, :2]
    u, v = fx * normalised[:, 0] + cx, fy * normalised[:, 1] + cy  # pinhole pixels
    coords = np.stack([v - 0.5, u - 0.5])
    out = np.empty(pixels.shape, dtype=np.float32)
    for c in range(pixels.shape[2]):
        plane = ndimage.map_coordinates(pixels[..., c].astype(np.float64), coords, order=3,
                                        mode="constant", cval=0.0)
        out[..., c] = np.maximum(plane, 0.0).reshape(h, w)
    return out


def distorted_variants(work, capture_dir, lit, lens: str) -> list[Variant]:
    """``distorted_<lens>`` (OPENCV model, the product undistorts) and
    ``distorted_<lens>_ignored`` (the same photos, the capture's PINHOLE model)."""
    from brdf_reconstruct.core.capture import colmap, undistort
    from testkit import synthetic

    k1, k2 = LENSES[lens]
    model = colmap.read_model(capture_dir / "sparse" / "0")
    by_name = {im.name: im for im in model.images}
    folder = work / f"distorted_{lens}"
    (folder / "lit").mkdir(parents=True)
    sparse = folder / "sparse" / "0"
    sparse.mkdir(parents=True)
    views = [(im.name, "OPENCV", [im.fx, im.fy, im.cx, im.cy, k1, k2, 0.0, 0.0], im.width,
              im.height, im.R_cam_from_world, im.t_cam_from_world) for im in model.images]
    synthetic.synthetic_reconstruction(views, model.xyz).write(str(sparse))
    entries, round_trip, round_trip_cubic, ignored_error, shift = [], [], [], [], []
    for (pixels, spec), entry in zip(lit, photo_entries(capture_dir), strict=True):
        im = by_name[entry["camera"]]
        params = [im.fx, im.fy, im.cx, im.cy, k1, k2, 0.0, 0.0]
        distorted = distort_photo(pixels, params, im.width, im.height)
        path = folder / "lit" / pathlib.Path(entry["image"]).name
        write_image(path, distorted, base_spec=spec)
        entries.append({"image": f"lit/{path.name}", "camera": entry["camera"],
                        "light": entry["light"]})
        # the resampling cost alone: distort -> the product's undistortion -> original
        obj = pixels[..., 3] >= 0.5
        ref = pixels[..., :3][obj].astype(np.float64)

        def error(image, ref=ref, obj=obj):
            return float(np.linalg.norm(np.nan_to_num(image[obj]) - ref) / np.linalg.norm(ref))

        for order, sink in ((1, round_trip), (3, round_trip_cubic)):
            sink.append(error(undistort.undistort_image(distorted[..., :3], "OPENCV", params,
                                                        im.width, im.height, order=order)))
        ignored_error.append(error(distorted[..., :3]))
        xy = undistort.distorted_positions("OPENCV", params, im.width, im.height)
        x, y = np.meshgrid(np.arange(im.width) + 0.5, np.arange(im.height) + 0.5)
        d = np.hypot(xy[..., 0] - x, xy[..., 1] - y)
        shift.append({"object_median_px": float(np.nanmedian(d[obj])),
                      "object_max_px": float(np.nanmax(d[obj])),
                      "frame_max_px": float(np.nanmax(d))})
    info = {"camera_model": "OPENCV", "k1": k1, "k2": k2, "p1": 0.0, "p2": 0.0,
            "distortion_shift": shift,
            "round_trip_rel_rmse_object": round_trip,
            "round_trip_rel_rmse_object_order3": round_trip_cubic,
            "ignored_rel_rmse_object": ignored_error,
            "round_trip_note": "relative RMSE against the original photo over the object's "
                               "pixels (EXR alpha >= 0.5): the distorted photo undistorted by "
                               "core.capture.undistort.undistort_image with the product's default "
                               "order 1 (bilinear; what the batch run does) and with order 3; "
                               "ignored: the distorted photo as it is (what a PINHOLE model "
                               "makes of it)"}
    ignored = folder.parent / f"distorted_{lens}_ignored"
    ignored.mkdir()
    shutil.copytree(folder / "lit", ignored / "lit")
    return [Variant(f"distorted_{lens}", folder, entries, sparse, info),
            Variant(f"distorted_{lens}_ignored", ignored, entries, None,  # PINHOLE model
                    {"camera_model": "PINHOLE (the capture's model)",
                     "photos": f"distorted_{lens}'s"})]


# --------------------------------------------------------------------------- runs


def run_batch(job: pathlib.Path, out: pathlib.Path, truth: np.ndarray) -> dict:
    """The batch entry on ``job`` in a fresh subprocess; the scores and the report."""
    from brdf_reconstruct.core.brdf import merl, metrics

    done, wall, load = common.run_batch(job)
    (out.parent / "batch.log").write_text(done.stdout + done.stderr)
    result = {"exit_status": done.returncode, "wall_s": wall, "load_1min": load}
    if done.returncode != 0:
        lines = [ln for ln in (done.stderr + done.stdout).splitlines() if ln.strip()]
        errors = [ln for ln in lines if ln.startswith("error:")]
        result["error"] = (errors or lines or ["(no output)"])[-1]
        return result
    table = merl.read(out / "brdf_0.binary")
    report = json.loads((out / "report.json").read_text())
    region = report["regions"][0]
    counts = region["counts"]
    result |= {"sphere_error": metrics.sphere_error(table, truth),
               "brdf_log_rmse": metrics.brdf_log_rmse(table, truth),
               "counts": {"observed": counts["observed"], "reliable": counts["reliable"],
                          "saturated": counts.get("saturated"),
                          "removed": counts.get("removed")},
               "skipped_assumptions": region.get("skipped_assumptions"),
               "winner_trial": region.get("winner"),
               "timings_s": report.get("timings_s"),
               "capture": report["capture"]}
    return result


def run_material(material: str, work: pathlib.Path, seeds: list[int]) -> dict:
    from brdf_reconstruct.core.brdf import database, merl, metrics
    from testkit import capture

    capture_dir, generated_s = common.ensure_capture(material, **CAPTURE)
    truth = merl.read(capture_dir / "truth.binary")
    spec = common.heldout_spec(material)
    made = database.make_table(spec)
    valid = np.isfinite(made) & np.isfinite(truth)
    work = work / material
    work.mkdir(parents=True)
    lit = [read_exr(capture_dir / e["image"]) for e in photo_entries(capture_dir)]

    baseline = [dict(e, image=str(capture_dir / e["image"])) for e in photo_entries(capture_dir)]
    plans = [Variant("exr", work / "exr", baseline, None,
                     {"job": "seed 0: capture.preset_job (the demo's job file); other seeds: "
                             "the same entries"})]
    plans[0].folder.mkdir()
    plans += [integer_variant(work, capture_dir, lit, kind) for kind in ("tiff16", "jpeg8",
                                                                          "png8")]
    plans.append(exposures_variant(work, capture_dir, lit))
    plans.append(integer_variant(work, capture_dir, lit, "clipped"))
    for lens in LENSES:
        plans.extend(distorted_variants(work, capture_dir, lit, lens))

    variants = {}
    for plan in plans:
        runs = {}
        for seed in seeds:
            if plan.name == "exr" and seed == 0:
                out = plan.folder / "out_s0"
                job = capture.preset_job(capture_dir, PRESET, out=out)
            else:
                job, out = write_job(plan.folder, capture_dir, plan.entries, plan.colmap_dir,
                                     seed)
            runs[seed] = result = run_batch(job, out, truth)
            if "error" in result:
                print(f"  {material} {plan.name} seed {seed}: FAILED ({result['error']})",
                      flush=True)
            else:
                c = result["counts"]
                print(f"  {material} {plan.name:28s} seed {seed}  sphere "
                      f"{result['sphere_error']:.4f}  log RMSE {result['brdf_log_rmse']:.4f}  "
                      f"observed {c['observed']} reliable {c['reliable']} saturated "
                      f"{c['saturated']}  {result['wall_s']:.1f} s", flush=True)
        headline = runs[seeds[0]]
        entry = {"prepared": plan.info, **headline}
        ok = [r for r in runs.values() if "error" not in r]
        entry["over_seeds"] = {
            "seeds": seeds, "failed": [s for s, r in runs.items() if "error" in r],
            **{key: {"median": float(np.median([r[key] for r in ok])),
                     "min": float(min(r[key] for r in ok)),
                     "max": float(max(r[key] for r in ok)),
                     "per_seed": {str(s): r.get(key) for s, r in runs.items()}}
               for key in ("sphere_error", "brdf_log_rmse") if ok},
            "reliable_per_seed": {str(s): r.get("counts", {}).get("reliable")
                                  for s, r in runs.items()},
            "wall_s_per_seed": {str(s): r["wall_s"] for s, r in runs.items()}}
        variants[plan.name] = entry
    base = variants["exr"]
    if "error" not in base:
        rec = merl.read(work / "exr" / f"out_s{seeds[0]}" / "brdf_0.binary")
        base["scored_against_make_table"] = {
            "sphere_error": metrics.sphere_error(rec, made),
            "brdf_log_rmse": metrics.brdf_log_rmse(rec, made),
            "note": "the demo scores against database.make_table(spec); truth.binary "
                    "is its MERL-file copy"}
        for v in variants.values():
            if "error" not in v:
                v["vs_baseline"] = {k: v[k] / base[k] for k in ("sphere_error",
                                                                 "brdf_log_rmse")}
                if "sphere_error" in v["over_seeds"]:
                    v["vs_baseline"]["median_over_seeds"] = {
                        k: v["over_seeds"][k]["median"] / base["over_seeds"][k]["median"]
                        for k in ("sphere_error", "brdf_log_rmse")}
    return {"capture": {"folder": str(capture_dir), "generated_now_s": generated_s,
                        "truth_binary_vs_make_table_max_abs": float(
                            np.max(np.abs(made[valid] - truth[valid])))},
            "variants": variants}


def plot(results: dict, path: pathlib.Path, seeds: list[int]) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    materials = list(results)
    names = list(next(iter(results.values()))["variants"])
    fig, axes = plt.subplots(2, 1, figsize=(12, 7.5), sharex=True)
    width = 0.8 / len(materials)
    x = np.arange(len(names))
    for ax, key, label in ((axes[0], "sphere_error", "rendered-sphere error"),
                           (axes[1], "brdf_log_rmse", "BRDF log RMSE")):
        for j, material in enumerate(materials):
            variants = results[material]["variants"]
            values = np.array([variants[n].get(key, np.nan) for n in names], dtype=float)
            at = x + (j - (len(materials) - 1) / 2) * width
            bars = ax.bar(at, values, width, color=f"C{j}",
                          label=f"{material.removeprefix('heldout_')}, seed {seeds[0]}")
            spread = [variants[n]["over_seeds"].get(key) for n in names]
            lo = [s["min"] if s else np.nan for s in spread]
            hi = [s["max"] if s else np.nan for s in spread]
            med = [s["median"] if s else np.nan for s in spread]
            ax.vlines(at, lo, hi, color="k", lw=1)
            ax.plot(at, med, "k_", ms=7, label="median, min-max over seeds "
                    + ",".join(map(str, seeds)) if j == 0 else None)
            for bar, n, value, top in zip(bars, names, values, hi, strict=True):
                if "error" in variants[n]:
                    ax.text(bar.get_x() + bar.get_width() / 2, 0, "failed", rotation=90,
                            ha="center", va="bottom", fontsize=7)
                else:
                    ax.text(bar.get_x() + bar.get_width() / 2, np.nanmax([value, top]),
                            f" {value:.3f}", rotation=90, ha="center", va="bottom",
                            fontsize=6)
            base = variants["exr"].get(key)
            if base is not None:
                ax.axhline(base, color=f"C{j}", ls="--", lw=0.8)
        ax.set_ylabel(label)
        ax.set_ylim(0, ax.get_ylim()[1] * 1.12)
    axes[0].legend(fontsize=7, title="dashed: exr baseline (seed 0)", title_fontsize=7,
                   loc="upper left")
    axes[0].set_title("Camera inputs through the batch entry (bunny capture, 3 lit photos "
                      "240 x 180, Balanced)", fontsize=10)
    axes[1].set_xticks(x, names, rotation=25, ha="right", fontsize=8)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--materials", default=",".join(MATERIALS),
                        help="comma-separated held-out materials")
    parser.add_argument("--work", default=None, help="working folder (default: a temporary "
                        "one, removed at the end)")
    parser.add_argument("--seeds", default="0,1,2,3", help="comma-separated seeds; the first "
                        "is the headline (the demo's 0)")
    parser.add_argument("--out", default=str(RESULTS / "camera_inputs.json"))
    args = parser.parse_args(argv)
    from testkit import capture

    t0 = time.perf_counter()
    seeds = [int(x) for x in args.seeds.split(",")]
    info = common.machine(NOTE)
    work = pathlib.Path(args.work or tempfile.mkdtemp(prefix="camera_inputs_"))
    if args.work and work.exists():
        shutil.rmtree(work)
    work.mkdir(parents=True, exist_ok=True)
    results = {}
    try:
        for material in args.materials.split(","):
            print(f"{material}:", flush=True)
            results[material] = run_material(material, work, seeds)
    finally:
        if args.work is None:
            shutil.rmtree(work, ignore_errors=True)
    command = "BRDF_RECONSTRUCT_CACHE=/work/main/.cache " + " ".join(
        [COMMAND, *(argv if argv is not None else sys.argv[1:])])
    document = {
        "command": command,
        "what": "The demo's capture turned into photos and job files as cameras and users "
                "produce them, each run through `python -m brdf_reconstruct.brdf_addon.batch "
                "job.toml` in a fresh subprocess, scored against the capture's truth.binary "
                "(core.brdf.metrics.sphere_error, brdf_log_rmse). vs_baseline: ratio to exr.",
        "capture": {"object": capture.default_subject(), **CAPTURE,
                    "resolution": list(CAPTURE["resolution"]),
                    "note": "seed: the capture's (scan noise), fixed; the batch runs' seeds are "
                            "settings.seeds"},
        "settings": {"preset": PRESET, "seeds": seeds,
                     "headline_seed": seeds[0], "peak_fraction": PEAK,
                     "clip_share_target": CLIP_SHARE, "base_exposure": BASE_EXPOSURE,
                     "exposure_factors": EXPOSURE_FACTORS,
                     "lenses": {k: {"k1": a, "k2": b, "p1": 0.0, "p2": 0.0}
                                for k, (a, b) in LENSES.items()}},
        "machine": common.machine_end(info),
        "total_seconds": time.perf_counter() - t0,
        "materials": results,
    }
    out = common.write_json(args.out, document, arguments=args)
    plot(results, out.with_suffix(".png"), seeds)
    print(f"wrote {out} and {out.with_suffix('.png')} in {document['total_seconds']:.0f} s")
    return 0


if __name__ == "__main__":
    sys.exit(main())
