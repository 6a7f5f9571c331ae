"""One reconstruction run, split where Blender must and must not be touched.

1. :func:`gather` (main thread, bpy): validates the scene, reads each photo as
   its camera produced it (``brdf_addon.photo_input``: colour space, saturation,
   size, lens distortion, exposure, irradiance reference), finds its light, and
   renders its G-buffers with Cycles (``brdf_addon.gbuffer``). Returns
   ``core.method.pipeline.PhotoInput`` arrays.
2. ``core.method.pipeline.run`` (any thread, no bpy): the science.
3. :func:`write_back` (main thread, bpy): writes ``brdf_<region>.binary``, the
   pictures and ``report.json`` to the output folder, fits and builds one NEW
   material per region (node group "BRDF Reconstruction"), measures its bake
   error, and fills ``scene.brdf.results``.

The operator (``operators.reconstruct``), the batch entry and the tests all
call these three. Nothing of the user's is modified: photos and masks are only
read, new materials are created (never assigned or edited in place), and
outputs go to new files in the output folder.
"""

from __future__ import annotations

import json
import os
import pathlib
import time

import bpy
import numpy as np

from ..core.brdf import merl
from ..core.method import pictures, pipeline, selection
from . import gbuffer, photo_input, prefs, props

# Lights for the bake error, camera space (+z to the viewer): not the fit's own
# error lights (core.bake.fitting.ERROR_LIGHTS); the fit itself sees no light.
BAKE_LIGHTS = np.array([[0.3, 0.2, 0.93], [-0.5, 0.4, 0.77]])


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


def gather(scene) -> list[pipeline.PhotoInput]:
    """Photos, lights and Cycles G-buffers for every photo of ``scene.brdf`` at once
    (:class:`ReconstructRun` does the same one photo per step). Raises
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
    """One line per thing done to the photos that the user should know: a scaled
    or undistorted photo, an exposure scale, saturated pixels, the irradiance rule."""
    lines = []
    photos = capture.get("photos", [])
    for p in photos:
        name = p.get("name", "")
        if p.get("scaled"):
            lines.append(f"{name}: {p['scaled']}")
        if p.get("undistorted"):
            lines.append(f"{name}: undistorted ({p['undistorted']})")
        if p.get("exposure") and p.get("exposure_scale", 1.0) != 1.0:
            lines.append(p["exposure"])
        if p.get("saturated_pixels"):
            lines.append(f"{name}: {p['saturated_pixels']} saturated pixels excluded")
        uncertainty = p.get("light", {}).get("uncertainty_deg")
        if uncertainty is not None:
            lines.append(f"{name}: sphere-probe light, uncertainty {uncertainty:.2f} deg")
    if len(photos) > 1 and all("assumed equally exposed" in p.get("exposure", "")
                               for p in photos):
        lines.append("no exposure EXIF: photos assumed equally exposed")
    return lines + list(capture.get("irradiance", []))


def output_dir(scene) -> pathlib.Path:
    path = pathlib.Path(bpy.path.abspath(scene.brdf.output_dir or "//brdf_out"))
    path.mkdir(parents=True, exist_ok=True)
    return path


def _as_image(name: str, picture: np.ndarray) -> bpy.types.Image:
    """A new Blender image holding a picture (row 0 = top; Blender stores bottom-up)."""
    h, w = picture.shape[:2]
    image = bpy.data.images.new(name, w, h, alpha=False)
    rgba = np.ones((h, w, 4), dtype=np.float32)
    rgba[..., :3] = picture[::-1]
    image.pixels.foreach_set(rgba.ravel())
    image.pack()
    return image


def write_back(scene, inputs, result: pipeline.PipelineResult, timings: dict,
               bake: bool = True, fits: dict | None = None,
               capture: dict | None = None) -> dict:
    """Write tables, pictures, materials and ``report.json``; fill ``scene.brdf.results``.

    Returns the report dict. Existing files of the same name in the output
    folder are replaced (they are this tool's outputs); nothing else is.
    ``fits``: {region: (winner, LobeFit)} made beforehand off the main thread;
    a region whose winner changed since (Cycles selection) is fitted here.
    ``capture``: what was applied to the photos (``gather_capture``), reported.
    """
    settings = scene.brdf
    out = output_dir(scene)
    labels = region_labels(settings.target, settings.region_mode)
    settings.results.clear()
    settings.capture_notes = json.dumps(capture_notes(capture or {}))
    regions = []
    for r in result.regions:
        label = labels.get(r.region, f"region {r.region}")
        entry = settings.results.add()
        entry.region, entry.label, entry.status, entry.reason = (
            r.region, label, r.status, r.reason)
        entry.counts = json.dumps(r.counts)
        summary = r.summary() | {"label": label}
        if r.status == "ok":
            t0 = time.perf_counter()
            table_path = out / f"brdf_{r.region}.binary"
            merl.write(table_path, r.table)
            entry.table_path = str(table_path)
            entry.winner, entry.kl = r.winner, float(r.kl[r.winner])
            views = pipeline.region_views(inputs, r.region)
            picture = None
            if views:
                v = views[0]
                render = selection.shade_gbuffer(r.table, v.normal, v.visibility, v.mask,
                                                 v.position, v.camera_center, v.light,
                                                 v.irradiance)
                picture = pictures.photo_vs_render(v.photo, render, v.mask)
            slice_pic = pictures.slice_image(r.table)
            pictures.write_png(out / f"brdf_{r.region}_slice.png", slice_pic)
            entry.slice_plot = _as_image(f"BRDF {label} slice", slice_pic)
            summary["pictures"] = [f"brdf_{r.region}_slice.png"]
            if picture is not None:
                pictures.write_png(out / f"brdf_{r.region}_photo_vs_render.png", picture)
                summary["pictures"].append(f"brdf_{r.region}_photo_vs_render.png")
            if views and r.reliable_pixels is not None:
                first = int(r.observed_pixels[0, 0])  # the first photo seeing the region
                overlay = pictures.reliable_overlay(
                    inputs[first].photo, r.observed_pixels[r.observed_pixels[:, 0] == first, 1:],
                    r.reliable_pixels[r.reliable_pixels[:, 0] == first, 1:])
                name = f"brdf_{r.region}_reliable_region.png"
                pictures.write_png(out / name, overlay)
                summary["pictures"].append(name)
                entry.plot = _as_image(f"BRDF {label} photo vs render", picture)
            summary["table"] = table_path.name
            timings[f"outputs_region_{r.region}"] = time.perf_counter() - t0
            if bake:
                t0 = time.perf_counter()
                fit = (fits or {}).get(r.region)
                fit = fit[1] if fit is not None and fit[0] == r.winner else None
                summary["material"] = _bake(scene, r, label, table_path, entry, fit)
                timings[f"bake_region_{r.region}"] = time.perf_counter() - t0
        regions.append(summary)
    report = {
        "settings": props.settings_dict(settings),
        "scan": settings.target.name,
        "photos": result.photo_counts,
        "capture": capture or {},
        "regions": regions,
        "timings_s": timings | {f"pipeline_{k}": v for k, v in result.timings.items()},
        "cycles": {
            # the fewest each comparison needs, as measured (see the README)
            "gbuffers": {"samples": 1, "bounces": 0, "pixel_filter_px": 0.01,
                         "why": "one sample at the pixel centre is exact geometry; "
                                "tests/test_blender_gbuffer.py"},
            "selection": {"path": settings.kl_path.lower(),
                          "samples": settings.kl_samples if settings.kl_path == "CYCLES"
                          else None, "bounces": 0,
                          "why": "bench/results/cycles_kl.json: the candidates' ranking "
                                 "is the same from 1 sample to 256"},
            "device": prefs.cycles_device(),
        },
        "blender": bpy.app.version_string,
    }
    (out / "report.json").write_text(json.dumps(report, indent=1, default=_json_default))
    return report


def _bake(scene, r, label, table_path, entry, fit=None) -> dict:
    """Fit the Cycles lobes to the table (unless given), build a NEW material,
    measure its bake error."""
    from ..core.bake import fitting
    from . import material

    fit = fit if fit is not None else fitting.fit(r.table)
    provenance = {"table_path": str(table_path),
                  "settings": props.settings_dict(scene.brdf),
                  "region": int(r.region), "kl": float(r.kl[r.winner]), "trial": int(r.winner)}
    mat = material.build_material(f"BRDF {label}", fit, provenance)
    errors = material.bake_error(mat, r.table, BAKE_LIGHTS)
    mat["brdf_bake_error"] = json.dumps(errors, default=_json_default)
    entry.material = mat
    entry.bake_error = float(errors["max"])
    return {"name": mat.name, "fit": json.loads(mat["brdf_fit"]), "bake_error": errors}


def _json_default(o):
    if isinstance(o, np.ndarray):
        return o.tolist()
    if isinstance(o, np.generic):
        return o.item()
    return str(o)


class ReconstructRun:
    """A run in steps, so a modal operator can keep Blender responsive.

    Each :meth:`step` does a bounded piece of work in the calling (main)
    thread: one photo's G-buffers, polling the worker, or writing back. The
    science (basis load and ``core.method.pipeline.run``) runs in a worker thread that
    never touches bpy. :meth:`cancel` stops at the next step boundary; until
    :meth:`step` reports done nothing has been written, so a cancelled run
    leaves the scene as it was. With ``threaded=False`` everything runs in the
    caller's thread (background mode, tests).
    """

    def __init__(self, scene, threaded: bool = True, bake: bool = True, on_progress=None):
        self.scene = scene
        self.threaded = threaded
        self.bake = bake
        self.on_progress = on_progress
        self.progress = 0.0
        self.message = "starting"
        self.report = None
        self._cancel = False
        self._inputs = []
        self._gathered = []
        self._capture = None
        self._photo = 0
        self._thread = None
        self._outcome = None
        self._timings = {}
        self._cycles_queue = None
        self._fits = {}
        self._t0 = time.perf_counter()
        check_scene(scene)
        self._settings = props.pipeline_settings(scene.brdf)
        self._n_photos = len(scene.brdf.photos)
        self._exposure = photo_input.exposure_plan(scene)

    @property
    def message(self) -> str:
        """What the run is doing now, one line; setting it calls ``on_progress(progress,
        message)`` (the batch entry prints it; the panel polls instead)."""
        return self._message

    @message.setter
    def message(self, text: str) -> None:
        self._message = text
        if self.on_progress is not None:
            self.on_progress(self.progress, text)

    def cancel(self) -> None:
        self._cancel = True

    def _cancelled(self) -> bool:
        return self._cancel

    def _science(self) -> None:
        try:
            t0 = time.perf_counter()
            basis = prefs.load_basis()
            self._timings["basis_load"] = time.perf_counter() - t0

            def progress(f, msg):
                self.progress, self.message = 0.3 + 0.6 * f, msg

            result = pipeline.run(basis, self._inputs, self._settings, progress=progress,
                                  cancelled=self._cancelled)
            if self.bake:  # the lobe fits are numpy: here, not in the main thread
                from ..core.bake import fitting

                for r in result.regions:
                    if self._cancel:
                        raise pipeline.Cancelled("cancelled by the user")
                    if r.status == "ok":
                        self.message = f"region {r.region}: fitting the material"
                        self._fits[r.region] = (r.winner, fitting.fit(r.table))
            self._outcome = ("ok", result)
        except pipeline.Cancelled as error:
            self._outcome = ("cancelled", error)
        except (ValueError, OSError) as error:
            self._outcome = ("error", error)

    def step(self) -> bool:
        """Advance; True when finished. Raises ValueError (one sentence) on a user
        error and ``pipeline.Cancelled`` after :meth:`cancel`."""
        if self._cancel:
            raise pipeline.Cancelled("cancelled by the user")
        if self._photo < self._n_photos:  # G-buffers: one photo per step (bpy)
            t0 = time.perf_counter()
            self.message = f"G-buffers {self._photo + 1}/{self._n_photos}"
            scales, notes = self._exposure
            self._gathered.append(photo_input.gather_photo(
                self.scene, self.scene.brdf.photos[self._photo], float(scales[self._photo]),
                notes[self._photo]))
            self._photo += 1
            if self._photo == self._n_photos:
                self._inputs, self._capture = capture_inputs(self._gathered)
            self.progress = 0.3 * self._photo / self._n_photos
            self._timings["gbuffers"] = self._timings.get("gbuffers", 0.0) + (
                time.perf_counter() - t0)
            return False
        if self._thread is None and self._outcome is None:
            t0 = time.perf_counter()
            if self.threaded:
                import threading

                self._thread = threading.Thread(target=self._science, daemon=True)
                self._thread.start()
                return False
            self._science()
            self._timings["science"] = time.perf_counter() - t0
        if self._thread is not None and self._thread.is_alive():
            return False
        status, value = self._outcome
        if status == "cancelled":
            raise value
        if status == "error":
            raise ValueError(str(value)) from value
        if self.scene.brdf.kl_path == "CYCLES" and self._cycles_step(value):
            return False
        self.progress, self.message = 0.9, "writing results"
        self._timings["total_before_outputs"] = time.perf_counter() - self._t0
        self.report = write_back(self.scene, self._inputs, value, self._timings, self.bake,
                                 self._fits, self._capture)
        self.progress, self.message = 1.0, "done"
        return True

    def _cycles_step(self, result) -> bool:
        """The accurate selection path, one candidate per step; True while work remains."""
        from . import cycles_select

        if self._cycles_queue is None:
            self._cycles_queue = [(r, t) for r in result.regions if r.status == "ok"
                                  for t in range(len(r.candidates))]
            self._cycles_total = max(len(self._cycles_queue), 1)
            self._cycles_kl = {}
        if not self._cycles_queue:
            return False
        t0 = time.perf_counter()
        r, t = self._cycles_queue.pop(0)
        s = self.scene.brdf
        self.message = f"region {r.region}: Cycles render of trial {t + 1}/{len(r.candidates)}"
        kl = cycles_select.score_candidate(self.scene, self._inputs, r.region,
                                           r.candidates[t].astype(np.float64), s.kl_samples,
                                           s.kl_bins, device=prefs.cycles_device())
        self._cycles_kl.setdefault(r.region, []).append(float(kl.mean()))
        if len(self._cycles_kl[r.region]) == len(r.candidates):
            scores = np.array(self._cycles_kl[r.region])
            winner = int(np.argmin(scores))
            r.selection = {"path": "cycles", "cycles_samples": int(s.kl_samples),
                           "cycles_bounces": 0, "fast_kl": [float(k) for k in r.kl],
                           "fast_winner": int(r.winner), "agree": winner == r.winner}
            r.kl, r.winner = scores, winner
            r.table = r.candidates[winner].astype(np.float64)
        done = self._cycles_total - len(self._cycles_queue)
        self.progress = 0.85 + 0.05 * done / self._cycles_total
        self._timings["cycles_selection"] = self._timings.get("cycles_selection", 0.0) + (
            time.perf_counter() - t0)
        return True

    def run(self) -> dict:
        """All steps in this thread (background mode); returns the report."""
        while not self.step():
            pass
        return self.report

