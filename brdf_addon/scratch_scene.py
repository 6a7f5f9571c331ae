"""One temporary scene for the extension's own renders, and the Cycles settings they use.

Three steps render in Cycles behind the user's back: the G-buffers of each photo
(``gbuffer``), the bake check of a new material (``material``) and the accurate
KL selection (``cycles_select``). Each builds a :class:`ScratchScene`: a new
scene plus every data-block made for it, all removed on exit, also after an
error or Esc, so the user's scenes, objects, meshes and materials are never
touched and nothing is left behind. Objects of the user's (the scan, a camera)
are linked into the scratch scene, never copied into theirs; a copy made for the
render is :meth:`ScratchScene.track`-ed and removed with the rest.

:func:`configure_cycles` is the one place the Cycles settings are written: the
rules every render shares (fixed seed, no adaptive sampling, no denoising, a
chosen number of bounces) and, by name, the two that only some need:
``point_sampled`` (every sample within 0.005 px of the pixel centre, so nothing
blends across silhouettes and a numpy twin can shade the same point) and
``exact_direct_light`` (no random termination of dim shadow rays, every bounce
kind off). :func:`float_exr_output` sets the linear 32-bit float EXR output.
Tests and benchmarks use the same two functions for their own renders.
"""

from __future__ import annotations

import contextlib
import os
import shutil
import tempfile

import bpy


def configure_cycles(scene, samples: int, *, device: str = "CPU", bounces: int = 0,
                     point_sampled: bool = False, exact_direct_light: bool = False,
                     adaptive: bool = False, denoise: bool = False, seed: int = 0) -> None:
    """Render ``scene`` with Cycles at ``samples`` samples per pixel on ``device``
    ("CPU" or "GPU"), ``bounces`` light bounces (0: direct light only), seed
    ``seed`` (not animated).

    point_sampled: the narrowest Blackman-Harris filter (Cycles' hard minimum
        width, 0.01 px). Not "BOX": Cycles ignores a box filter's width and
        jitters over the whole pixel. False keeps Cycles' default filter.
    exact_direct_light: every bounce kind (diffuse, glossy, transmission,
        volume, transparent) set to ``bounces``, light-sampling threshold 0 (no
        random termination of dim shadow rays), direct clamp off, no camera or
        distance culling.
    adaptive, denoise: Cycles' adaptive sampling and denoiser (default off:
        renders stay unbiased and repeatable).
    """
    scene.render.engine = "CYCLES"
    cycles = scene.cycles
    cycles.device = device
    cycles.samples = samples
    cycles.use_adaptive_sampling = adaptive
    cycles.use_denoising = denoise
    cycles.seed = seed
    cycles.use_animated_seed = False
    cycles.max_bounces = bounces
    if exact_direct_light:
        for kind in ("diffuse_bounces", "glossy_bounces", "transmission_bounces",
                     "volume_bounces", "transparent_max_bounces"):
            setattr(cycles, kind, bounces)
        cycles.light_sampling_threshold = 0.0
        cycles.sample_clamp_direct = 0.0
        cycles.use_camera_cull = False
        cycles.use_distance_cull = False
    if point_sampled:
        cycles.pixel_filter_type = "BLACKMAN_HARRIS"
        cycles.filter_width = cycles.bl_rna.properties["filter_width"].hard_min


def float_exr_output(scene, *, multilayer: bool = False, color_mode: str | None = None) -> None:
    """Write renders as linear 32-bit float EXR (ZIP), "Standard" view transform
    (no AgX/Filmic look, exposure 0, gamma 1). multilayer: one channel per pass
    (``ViewLayer.Normal.X`` ...). color_mode: "RGB" or "RGBA", else Blender's
    default for the format."""
    image = scene.render.image_settings
    if multilayer:
        image.media_type = "MULTI_LAYER_IMAGE"
        image.file_format = "OPEN_EXR_MULTILAYER"
    else:
        image.file_format = "OPEN_EXR"
    image.color_depth = "32"
    image.exr_codec = "ZIP"
    if color_mode is not None:
        image.color_mode = color_mode
    view = scene.view_settings
    view.view_transform = "Standard"
    view.look = "None"
    view.exposure = 0.0
    view.gamma = 1.0


class ScratchScene:
    """A temporary scene named ``name`` and every data-block made for it.

    ``with ScratchScene(name) as scratch:`` gives ``scratch.scene`` (no world,
    render size as the user's scene is not copied: set what the render needs) and
    ``scratch.folder``, a temporary folder for render files. On exit, also after
    an error, every block made through :meth:`new` or handed to :meth:`track` is
    removed in reverse order, with the scene; with ``remove_new_images`` also the
    images that appeared meanwhile (the "Render Result"); the folder (made inside
    ``tmpdir``, default the system's temporary folder) is deleted.
    """

    def __init__(self, name: str, *, remove_new_images: bool = False, tmpdir=None):
        self.name = name
        self.tmpdir = tmpdir
        self.remove_new_images = remove_new_images
        self.created: list = []  # (collection, data-block), removed in reverse order
        self.scene = None
        self.folder = None

    def new(self, collection, *args):
        """``collection.new(*args)`` (e.g. ``bpy.data.lights, name, "SUN"``), tracked."""
        return self.track(collection, collection.new(*args))

    def track(self, collection, block):
        """Remove ``block`` from ``collection`` (e.g. ``bpy.data.objects``) on exit."""
        self.created.append((collection, block))
        return block

    def __enter__(self) -> ScratchScene:
        self._images_before = set(bpy.data.images) if self.remove_new_images else set()
        self.folder = tempfile.mkdtemp(prefix="brdf_scratch_", dir=self.tmpdir)
        try:
            self.scene = self.new(bpy.data.scenes, self.name)
            self.scene.world = None
        except BaseException:
            self.__exit__(None, None, None)
            raise
        return self

    def render(self, filename) -> str:
        """Render the scene's camera to ``filename``: a bare name goes in
        :attr:`folder`; a path with a folder (absolute, or relative to the working
        folder) is kept where it points. Returns the absolute path written."""
        filename = os.fspath(filename)
        if os.path.dirname(filename):
            path = os.path.abspath(filename)
        else:
            path = os.path.join(self.folder, filename)
        self.scene.render.filepath = path
        with bpy.context.temp_override(scene=self.scene):
            bpy.ops.render.render(write_still=True, scene=self.scene.name)
        return path

    def __exit__(self, *exc) -> bool:
        for collection, block in reversed(self.created):
            with contextlib.suppress(ReferenceError):  # already gone with its owner
                collection.remove(block)
        self.created.clear()
        if self.remove_new_images:
            for image in set(bpy.data.images) - self._images_before:
                bpy.data.images.remove(image)
        if self.folder is not None:
            shutil.rmtree(self.folder, ignore_errors=True)  # our own folder, all of it
            self.folder = None
        return False
