"""Settings of the reconstruction, held by one PropertyGroup on the scene.

``Scene.brdf`` (:class:`BRDFSettings`) holds the target object, the list of
lit photos (:class:`BRDFPhoto`), every reliable-region, sampling, trial and KL
setting, the seed, the run state, and the results per region
(:class:`BRDFRegionResult`). The setting names match the ``[settings]`` table
of the batch job file (``brdf_addon.job``), so the panel, the batch entry and
the tests share one vocabulary. Angles (``peak_max_angle``, ``north_offset``) are
Blender ``ANGLE`` properties: radians in Python, degrees in the UI; the job file
gives them in degrees (``brdf_addon.job.apply`` converts, :func:`settings_dict`
converts back).

Choosing a preset sets the values it names (:data:`presets.PRESETS`); editing one
of them afterwards to a value other than the preset's turns ``preset`` to
``"CUSTOM"`` (the ``update`` callbacks :func:`_apply_preset` and
:func:`_preset_value_changed`).
"""

import math

import bpy
from bpy.props import (
    BoolProperty,
    CollectionProperty,
    EnumProperty,
    FloatProperty,
    FloatVectorProperty,
    IntProperty,
    PointerProperty,
    StringProperty,
)
from bpy.types import PropertyGroup

from .job import SETTING_NAMES
from .presets import HINTS, PRESETS

# Blender 4.5+ warns on "//" paths unless the property says it takes them
PATH = {"PATH_SUPPORTS_BLEND_RELATIVE"} if bpy.app.version >= (4, 5, 0) else set()

# Presets: brdf_addon/presets.py (plain data, measured by bench/tradeoff.py). The
# settings' defaults are the Balanced preset, the default preset.
_BALANCED = PRESETS["BALANCED"]

LIGHT_SOURCES = [
    ("SUN_OBJECT", "Sun Object", "Direction of a Sun light object in the scene"),
    ("DIRECTION", "Direction", "A world-space direction towards the light"),
    ("PROBE", "Sphere Probe", "From the highlight on a mirror or glossy black sphere photo"),
    ("SUN_POSITION", "Date, Time, Place", "The sun's direction from when and where the "
     "photo was taken (creates or updates a Sun object)"),
]


COLOR_SPACES = [
    ("AUTO", "Auto", "Float EXR/TIFF and 16/32-bit TIFF are linear; 8/16-bit PNG and JPEG "
     "are sRGB unless the file says linear"),
    ("SRGB", "sRGB", "Decode the sRGB transfer curve"),
    ("LINEAR", "Linear", "The values are linear radiance already (not for 8-bit files)"),
]

REFERENCES = [
    ("NONE", "None", "Irradiance as given (equal across photos unless you set it)"),
    # the identifier stays "CARD" (and the job key grey_card): only the UI says Gray
    ("CARD", "Gray Card", "A gray card facing the light, marked by the reference mask"),
    ("SCAN", "Diffuse Region", "A diffuse part of the scan, marked by the reference mask"),
]


def _is_camera(_self, obj):
    return obj.type == "CAMERA"


def _is_sun(_self, obj):
    return obj.type == "LIGHT" and obj.data.type == "SUN"


def _is_mesh(_self, obj):
    return obj.type == "MESH"


class BRDFPhoto(PropertyGroup):
    """One lit photo: image file, camera, light and irradiance (``scene.brdf.photos``)."""

    filepath: StringProperty(name="Image", subtype="FILE_PATH", options=PATH,
                             description="Linear EXR/TIFF, or sRGB PNG/JPEG, of the lit object")
    camera: PointerProperty(name="Camera", type=bpy.types.Object, poll=_is_camera,
                            description="Camera the photo was taken from")
    light_source: EnumProperty(name="Light", items=LIGHT_SOURCES, default="SUN_OBJECT",
                               description="Where the direction of the photo's light "
                               "comes from")
    sun: PointerProperty(name="Sun", type=bpy.types.Object, poll=_is_sun,
                         description="Sun light whose direction is the photo's light")
    direction: FloatVectorProperty(name="Direction", size=3, subtype="DIRECTION",
                                   default=(0.0, 0.0, 1.0),
                                   description="World direction towards the light")
    probe_path: StringProperty(name="Probe Photo", subtype="FILE_PATH", options=PATH,
                               description="Photo of a mirror or glossy black sphere")
    when: StringProperty(name="Date and Time", default="2026-06-21 12:00:00",
                         description="Local date and time of the photo, YYYY-MM-DD HH:MM:SS")
    utc_offset: FloatProperty(name="UTC Offset", default=0.0, min=-14.0, max=14.0,
                              description="Hours east of Greenwich of that local time "
                              "(daylight saving included)")
    # Latitude and longitude are geographic coordinates, not rotations: degrees are
    # how they are written (GPS EXIF, maps) and what the solar position takes
    # (core.capture.sun), so they stay plain floats in degrees.
    latitude: FloatProperty(name="Latitude", default=0.0, min=-90.0, max=90.0,
                            description="Geographic latitude of the place, degrees north")
    longitude: FloatProperty(name="Longitude", default=0.0, min=-180.0, max=180.0,
                             description="Geographic longitude of the place, degrees east")
    # radians (Blender shows degrees); the job file's north_offset is degrees
    north_offset: FloatProperty(name="North Offset", subtype="ANGLE", default=0.0,
                                min=-math.pi, max=math.pi,
                                description="Angle from the scene's +Y to geographic north, "
                                "counter-clockwise seen from above")
    irradiance: FloatVectorProperty(name="Irradiance", size=3, min=1e-9, soft_max=100.0,
                                    default=(1.0, 1.0, 1.0), subtype="COLOR",
                                    description="Light's irradiance, W/m^2 per channel")
    mask_path: StringProperty(name="Mask", subtype="FILE_PATH", options=PATH,
                              description="Optional mask image: white = use the pixel")
    silhouette_margin: IntProperty(
        name="Silhouette Margin", default=0, min=0, soft_max=20,
        description="The scan's silhouette, rendered from the photo's camera, is always the "
        "mask (with the mask image, if any); this shrinks it by so many pixels, where a "
        "scan and its photo disagree at the outline")
    color_space: EnumProperty(name="Color Space", items=COLOR_SPACES, default="AUTO",
                              description="How the photo's values map to linear radiance")
    exposure: FloatProperty(name="Exposure Scale", default=0.0, min=0.0, soft_max=100.0,
                            description="Factor bringing this photo to the first photo's "
                            "radiometric scale (0 = from the EXIF shutter, aperture and ISO)")
    reference_kind: EnumProperty(name="Irradiance Reference", items=REFERENCES,
                                 default="NONE",
                                 description="What in the photo measures its irradiance "
                                 "relative to the other photos")
    reference_mask_path: StringProperty(
        name="Reference Mask", subtype="FILE_PATH", options=PATH,
        description="Mask of the gray card, or of a diffuse part of the scan, in this photo")
    probe_center: FloatVectorProperty(name="Sphere Center", size=2, default=(0.0, 0.0),
                                      description="The sphere's center in the probe photo, "
                                      "pixels from the top-left corner (x right, y down)")
    probe_radius: FloatProperty(name="Sphere Radius", default=0.0, min=0.0,
                                description="The sphere's radius in the probe photo, pixels "
                                "(0 = find the sphere automatically)")
    time_from_exif: BoolProperty(name="Time from EXIF", default=False,
                                 description="Take the date and time (and UTC offset, where "
                                 "the camera wrote one) from the photo's EXIF")
    place_from_exif: BoolProperty(name="Place from GPS", default=False,
                                  description="Take latitude and longitude from the photo's "
                                  "GPS EXIF")


class BRDFRegionResult(PropertyGroup):
    """What a reconstruction produced for one region (``scene.brdf.results``)."""

    region: IntProperty(name="Region",
                        description="Index of the region (material slot or face set)")
    label: StringProperty(name="Region Name",
                          description="Name of the region: its material, or its slot or "
                          "face set number")
    status: StringProperty(name="Status",
                           description="\"ok\" if the region got a BRDF, else \"skipped\"")
    reason: StringProperty(name="Reason",
                           description="Why the region was skipped (empty if it was not)")
    winner: IntProperty(name="Chosen Trial", default=-1,
                        description="The trial the KL selection chose (-1 = none)")
    kl: FloatProperty(name="KL", description="KL divergence of the chosen trial, nats")
    notes: StringProperty(name="Notes", default="[]",
                          description="What the user should read about the region's table "
                          "(JSON list of lines): e.g. photos brighter than the irradiance "
                          "given lets them be")
    counts: StringProperty(name="Sample Counts",
                           description="Pixels of the region as JSON: observed, removed "
                           "per stage, reliable")
    bake_error: FloatProperty(name="Bake Error", default=-1.0,
                              description="Relative RMSE of the baked material against the "
                              "table, under lights not used for fitting (-1 = not measured)")
    material: PointerProperty(name="Material", type=bpy.types.Material,
                              description="The material baked from the chosen table")
    table_path: StringProperty(name="Table", subtype="FILE_PATH", options=PATH,
                               description="The MERL .binary table the run wrote for the "
                               "region")
    plot: PointerProperty(name="Photo vs Render", type=bpy.types.Image,
                          description="The photo and the chosen trial's render, same exposure")
    slice_plot: PointerProperty(name="BRDF Slice", type=bpy.types.Image,
                                description="The table at phi_d = 90 deg: theta_h across, "
                                "theta_d down, log scale")


# True while _apply_preset sets a preset's values, so that its own assignments do
# not turn the preset Custom (updates run on the main thread, one at a time)
_applying_preset = False


def _apply_preset(self, _context):
    """Update of ``preset``: set the chosen preset's values (Custom sets none)."""
    global _applying_preset
    values = PRESETS.get(self.preset)
    if values is None:
        return
    _applying_preset = True
    try:
        for key, value in values.items():
            setattr(self, key, value)
    finally:
        _applying_preset = False


def _differs(value, preset_value) -> bool:
    if isinstance(preset_value, float):  # stored as float32
        return not math.isclose(value, preset_value, rel_tol=1e-6, abs_tol=1e-9)
    return value != preset_value


def _preset_value_changed(self, _context):
    """Update of each setting a preset names: a value other than the chosen preset's
    makes the preset Custom; the preset's own value keeps it."""
    if _applying_preset:
        return
    values = PRESETS.get(self.preset)
    if values is not None and any(_differs(getattr(self, k), v) for k, v in values.items()):
        self.preset = "CUSTOM"


class BRDFSettings(PropertyGroup):
    """Scene-wide settings, reached as ``scene.brdf``."""

    target: PointerProperty(name="Scan", type=bpy.types.Object, poll=_is_mesh,
                            description="The photogrammetry mesh to give a BRDF")
    region_mode: EnumProperty(
        name="Regions", default="MATERIAL_SLOT",
        description="How the scan is split into regions, one BRDF each",
        items=[("MATERIAL_SLOT", "Material Slots", "One BRDF per material slot (an object "
                "without slots is one region)"),
               ("FACE_SET", "Face Sets", "One BRDF per sculpt face set (a mesh without "
                "face sets is one region)")])
    photos: CollectionProperty(type=BRDFPhoto, name="Photos",
                               description="The lit photos, each with its camera and light")
    active_photo: IntProperty(name="Active Photo", default=0, min=0,
                              description="Index of the photo selected in the list")

    # reliable region (paper Sec. 3.1)
    use_curvature: BoolProperty(name="Curvature", default=True,
                                description="Drop pixels of high image-space curvature")
    curvature_threshold: FloatProperty(name="Curvature Threshold", default=0.2, min=0.0,
                                       description="Largest |H| kept, radians of normal turn "
                                       "per 10 pixels (the paper's 0.2)")
    use_monotonicity: BoolProperty(name="Monotonicity", default=True,
                                   description="Drop pixels breaking monotonicity in n.h (Eq. 1)")
    monotonicity_tolerance: FloatProperty(name="Monotonicity Tolerance", default=1.0,
                                          min=0.0, description="Allowed factor (1 + tolerance) "
                                          "off the monotone fit")
    use_brightest: BoolProperty(name="Brightest Peak", default=True,
                                description="Take the brightest pixel as the specular peak "
                                "(Eq. 2)")
    # radians (Blender shows degrees); the job file's peak_max_angle is degrees
    peak_max_angle: FloatProperty(name="Peak Max Angle", subtype="ANGLE",
                                  default=math.radians(30.0), min=0.0, max=math.pi,
                                  description="Eq. 2 only if the brightest pixel's normal is "
                                  "within this angle of h")
    clip_level: FloatProperty(name="Saturation Level", default=0.0, min=0.0,
                              description="Pixels with a channel at or above this linear "
                              "value of the file (before exposure scaling) are saturated and "
                              "left out (0 = none). A file's own white level (an integer "
                              "file's largest code, 1.0; a float file's plateau) is only "
                              "reported: those pixels are used at their value")
    scene_up: FloatVectorProperty(name="Scene Up", size=3, subtype="DIRECTION",
                                  default=(0.0, 0.0, 1.0),
                                  description="World direction of the sky (the sun's zenith); "
                                  "COLMAP worlds are rarely +Z up: see Up from Cameras")
    min_cosine: FloatProperty(name="Min Cosine", default=0.1, min=0.0, max=1.0,
                              description="Smallest n.l and n.v kept (grazing limit)")

    # sampling and trials (paper Sec. 3.2)
    preset: EnumProperty(
        name="Preset", default="BALANCED", update=_apply_preset,
        description="Samples, trials and selection: a measured speed/accuracy trade (Fast, "
        "Balanced, Accurate) or the paper's own mode (Paper); changing one of them makes "
        "the preset Custom",
        # numbered: a .blend stores the number, and Custom was 3 before Paper came
        items=[("FAST", "Fast", HINTS["FAST"], 0),
               ("BALANCED", "Balanced", HINTS["BALANCED"], 1),
               ("ACCURATE", "Accurate", HINTS["ACCURATE"], 2),
               ("PAPER", "Paper", HINTS["PAPER"], 4),
               ("CUSTOM", "Custom", "Your own samples, trials and selection", 3)])
    samples: IntProperty(name="BRDF Samples", default=_BALANCED["samples"], min=1, soft_max=200,
                         update=_preset_value_changed,
                         description="Optimal BRDF samples per trial (paper: 6)")
    sampler: EnumProperty(
        name="Sampler", default="CONDITION",
        description="The criterion that chooses each trial's BRDF samples",
        items=[("CONDITION", "Condition Number (paper)", "Minimise the condition number "
                "of the samples' basis rows, as the paper and Nielsen et al. do (in the "
                "photo pipeline as good as Bayes risk or better, as measured)"),
               ("RISK", "Bayes Risk", "Minimise the reconstruction's expected error "
                "(better on held-out measured materials from exact values; in the photo "
                "pipeline a tie or slightly worse, and 4x faster to choose)")])
    trials: IntProperty(name="Trials", default=_BALANCED["trials"], min=1, soft_max=128,
                        update=_preset_value_changed,
                        description="Random-subset reconstructions; KL picks one")
    subset_fraction: FloatProperty(name="Subset Fraction",
                                   default=_BALANCED["subset_fraction"], min=0.01, max=1.0,
                                   update=_preset_value_changed,
                                   description="Share of reliable pixels each trial draws")
    min_reliable_samples: IntProperty(name="Min Reliable Samples", default=20, min=1,
                                      description="Regions with fewer are skipped")
    keep_highlight_energy: BoolProperty(
        name="Keep Highlight Energy", default=_BALANCED["keep_highlight_energy"],
        update=_preset_value_changed,
        description="After the selection, refit the chosen table so that the light it "
        "reflects, summed over each photo, matches the photo's, with no pixel brighter "
        "than the brightest photographed. On blunted scans it keeps the highlights the "
        "trials lose (median sphere error 0.40 to 0.28 on the bunny, 0.67 to 0.53 on "
        "Spot); kept as it is where the trial already holds the photos' energy or the "
        "photos disagree on it; off in the paper's method")
    photo_consistent: FloatProperty(
        name="Every-Pixel Threshold", default=0.2, min=0.0, max=1.0,
        description="With Keep Highlight Energy: where the chosen table refitted to every "
        "observed pixel reproduces each photo to this relative RMSE and, refitted "
        "without each photo, mostly predicts it and barely moves (or predicts it to "
        "half the chosen trial's own error), it replaces the energy refit (accurate "
        "scans: the photos read pixel by pixel). 0 turns it off")
    refine_to_photos: BoolProperty(
        name="Refine to Photos", default=False,
        description="After the selection, refit the chosen table to every observed pixel "
        "(highlights included), reflecting no more light than it receives. Needs "
        "accurate normals: with exact ones it cut the median sphere error from 0.23 to "
        "about 0.07; on a blunted scan it was even (0.39 against 0.40), and with noisy "
        "normals it can overshoot a mirror's peak. Off by default")
    pixel_footprint: BoolProperty(
        name="Pixel Footprint", default=_BALANCED["pixel_footprint"],
        update=_preset_value_changed,
        description="Also render the scan's normals at 2 x 2 points of each photo pixel, "
        "so the refits to every pixel predict what a camera's pixel records: the light "
        "over its area, not at its center. Pays on accurate scans (exact normals, Cycles "
        "photos: sphere error 0.126 to 0.104 on the bunny, 0.134 to 0.081 on Spot; "
        "blunted scans unchanged) for about 1.3 to 2 s more per run; on in Accurate")

    # texture (issue 16)
    texture: BoolProperty(
        name="Texture", default=False,
        description="Reconstruct a color per texel on the scan's UV map: one shared BRDF "
        "shape per region, its albedo per texel from the lit photos (the scan's own "
        "texture as the prior and where no photo sees it). Needs a UV map")
    texture_size: IntProperty(
        name="Texture Size", default=0, min=0, max=8192,
        description="Width and height in texels of the reconstructed texture; 0: the "
        "scan's own texture's size, or 512 without one")
    uv_map: StringProperty(
        name="UV Map", default="",
        description="The scan's UV map the texture lies on (empty: its active render map)")

    material_model: EnumProperty(
        name="Material", default="NODE_GROUP",
        description="What the new material is made of (the bake error of both is "
        "measured and reported)",
        items=[("NODE_GROUP", "BRDF Node Group", "The \"BRDF Reconstruction\" node group: "
                "the closures the bake fits, for Cycles"),
               ("PRINCIPLED", "Principled BSDF", "A Principled BSDF derived from the same "
                "fit, for Eevee, the glTF exporter and other engines (less exact)")])

    export_gltf: BoolProperty(
        name="Export glTF", default=False,
        description="Also write brdf_scan.glb to the output folder: a copy of the scan "
        "wearing each region's Principled BSDF version (with its texture), through "
        "Blender's glTF exporter, for other engines and tools")

    # KL selection
    kl_path: EnumProperty(
        name="Selection", default=_BALANCED["kl_path"], update=_preset_value_changed,
        description="How the trials' tables are compared with the photos to choose one",
        items=[("FAST", "Fast (numpy)", "Shade each candidate table on the G-buffers"),
               ("CYCLES", "Accurate (Cycles)", "Render each candidate table in Cycles")])
    kl_bins: IntProperty(name="KL Bins", default=64, min=4, max=4096,
                         description="Bins of the log-intensity histograms that the KL "
                         "divergence compares")
    kl_samples: IntProperty(name="Cycles Samples", default=_BALANCED["kl_samples"], min=1,
                            max=4096, update=_preset_value_changed,
                            description="Cycles samples per KL render")
    seed: IntProperty(name="Seed", default=0, min=0,
                      description="Seed of every random choice (sampling trials); "
                      "same seed, same result")
    basis: EnumProperty(
        name="Basis", default="PREFERENCES",
        description="The PCA basis of BRDFs the reconstruction stands on, for this scene",
        items=[("PREFERENCES", "From Preferences", "The basis chosen in the extension's "
                "preferences"),
               ("ANALYTIC", "Analytic", "The built-in basis of 150 analytic materials (no "
                "data license)"),
               ("MEASURED", "Measured (MERL)", "80 measured MERL materials as neural BRDFs, "
                "shipped (the default); the MERL data behind them are for research use: "
                "for other use read MERL's terms first, or choose Analytic"),
               ("FOLDER", "MERL Folder", "Your own folder of MERL .binary files (Basis "
                "Folder)")])
    basis_folder: StringProperty(name="Basis Folder", subtype="DIR_PATH", default="",
                                 options=PATH,
                                 description="Folder of MERL .binary files for the Folder "
                                 "basis")
    output_dir: StringProperty(name="Output", subtype="DIR_PATH", default="//brdf_out",
                               options=PATH,
                               description="Folder for the .binary tables, report and plots")
    overwrite: BoolProperty(name="Overwrite", default=False,
                            description="Replace files of the same names in the output "
                            "folder that no earlier run wrote (tables, pictures, report)")

    # run state (not saved as settings)
    settings_version: IntProperty(
        name="Settings Version", default=0, min=0, options={"HIDDEN"},
        description="Which version of these settings the file was saved with "
        "(brdf_addon/versioning.py; 0 = 0.1.0, angles in degrees)")
    running: BoolProperty(name="Running", default=False, options={"SKIP_SAVE"},
                          description="A reconstruction is running")
    progress: FloatProperty(name="Progress", default=0.0, min=0.0, max=1.0,
                            subtype="FACTOR", options={"SKIP_SAVE"},
                            description="Share of the running reconstruction done")
    status: StringProperty(name="Status", default="",
                           description="What the running reconstruction is doing (on "
                           "its progress bar)")
    results: CollectionProperty(type=BRDFRegionResult, name="Results",
                                description="What the last reconstruction gave per region")
    capture_notes: StringProperty(name="Capture Notes", default="[]",
                                  description="What the last run did to the photos (JSON "
                                  "list of lines): scaling, undistortion, exposure, "
                                  "saturation, the irradiance rule")


CLASSES = (BRDFPhoto, BRDFRegionResult, BRDFSettings)


def pipeline_settings(settings):
    """``core.method.pipeline.PipelineSettings`` from ``scene.brdf`` (angles are radians
    in both)."""
    from ..core.method import observations, pipeline, reliable

    return pipeline.PipelineSettings(
        reliable=reliable.ReliableSettings(
            use_curvature=settings.use_curvature,
            curvature_threshold=settings.curvature_threshold,
            use_monotonicity=settings.use_monotonicity,
            monotonicity_tolerance=settings.monotonicity_tolerance,
            use_brightest=settings.use_brightest,
            peak_max_angle=settings.peak_max_angle),
        observation=observations.ObservationSettings(
            min_cosine=settings.min_cosine,
            # the clip level is applied to the file's values before exposure scaling,
            # where each photo's saturated mask is made (brdf_addon.photo_input)
            clip_level=None),
        n_samples=settings.samples, n_trials=settings.trials,
        subset_fraction=settings.subset_fraction,
        min_reliable_samples=settings.min_reliable_samples, kl_bins=settings.kl_bins,
        seed=settings.seed, sampler=settings.sampler.lower(),
        refine=("photo" if settings.refine_to_photos
                else "energy" if settings.keep_highlight_energy else "none"),
        photo_consistent=settings.photo_consistent)


def footprint_used(settings) -> bool:
    """Whether a run renders the pixel footprint (``pixel_footprint``): only a refit
    (``keep_highlight_energy``, ``refine_to_photos``) reads it, so without one (the
    Paper preset) it is not rendered."""
    return bool(settings.pixel_footprint
                and (settings.keep_highlight_energy or settings.refine_to_photos))


def settings_dict(settings) -> dict:
    """The job-file ``[settings]`` of ``scene.brdf`` (for reports and provenance): as a
    job file writes them, so angles in degrees (rounded to 1e-4 degree, finer than
    their float32 storage in radians at 180 degrees)."""
    out = {}
    for name in SETTING_NAMES:
        value = getattr(settings, name)
        if settings.bl_rna.properties[name].subtype == "ANGLE":
            value = round(math.degrees(value), 4)
        out[name] = value
    return out


def attach() -> None:
    """Attach the settings as ``bpy.types.Scene.brdf`` (after class registration)."""
    bpy.types.Scene.brdf = PointerProperty(type=BRDFSettings)


def detach() -> None:
    """Remove ``bpy.types.Scene.brdf`` (before class unregistration)."""
    del bpy.types.Scene.brdf
