"""G-buffers as arrays: the per-pixel geometry of one photo, decoded from the
multilayer EXR that Cycles writes (``brdf_addon/gbuffer.py`` renders it).

Channels (Blender's names, layer ``LAYER``): ``Combined.A`` (coverage),
``Normal.XYZ`` and ``Position.XYZ`` (world space, averaged over the pixel's
samples, background ones giving 0), ``Diffuse Direct.RGB`` (a white Lambertian
surface under a Sun of strength pi W/m^2: ``vis * max(n.l, 0)``) and the AOV
``REGION_AOV.X`` (the region id), and when asked for the colour AOV
``UV_AOV.RGB`` (the scan's UV map: u, v, 0). Images have row 0 at the top, column 0 at the
left (EXR and numpy order). No bpy; the file is read by
``core.capture.photo_io.read_multilayer_exr``.
"""

from __future__ import annotations

import dataclasses

import numpy as np

LAYER = "ViewLayer"
REGION_AOV = "brdf_region"
UV_AOV = "brdf_uv"
# Below this n.l the visibility ratio is ill-conditioned; such points count as unlit.
MIN_COSINE = 1e-6


@dataclasses.dataclass(frozen=True)
class GBuffers:
    """Per-pixel geometry of one photo, full photo size (H, W).

    normal: (H, W, 3) float64, world space, unit: the shading normal as rendered
        (interpolated on smooth faces, towards the camera on back faces); 0 on
        background.
    position: (H, W, 3) float64, world space, scene units; 0 on background.
    visibility: (H, W) float64 in [0, 1]: fraction of the distant light reaching
        the point, from cast shadows by the scan itself (1 = lit); 0 where the
        shading normal faces away from the light (n.l <= 0) and on background.
    region: (H, W) int32: material slot index of the visible face (0 for an object
        without slots; indices past the last slot clamp to it, as Blender's
        renderers do); -1 on background.
    mask: (H, W) bool: pixels covered by the object (coverage >= 1/2) with finite
        geometry. ``region >= 0`` exactly where ``mask``.
    camera_center: (3,) float64, world space. For an orthographic camera, a point
        very far behind the camera on its axis, so that ``normalize(C - P)`` is the
        (parallel) view direction; see ``orthographic``.
    orthographic: True for an orthographic camera.
    uv: (H, W, 2) float64 the scan's UV map (u right, v up; averaged over the
        pixel's samples like the normal), NaN on background; None when not rendered.
    window: (row_start, row_stop, col_start, col_stop), half-open, of the rendered
        crop; None when the full frame was rendered; an empty window when the
        object projects outside the frame (nothing rendered). Outside it is
        background.
    """

    normal: np.ndarray
    position: np.ndarray
    visibility: np.ndarray
    region: np.ndarray
    mask: np.ndarray
    camera_center: np.ndarray
    orthographic: bool = False
    window: tuple[int, int, int, int] | None = None
    uv: np.ndarray | None = None

    @property
    def shape(self) -> tuple[int, int]:
        """(H, W) of the images."""
        return self.mask.shape


def empty(height, width, center, ortho, window, uv: bool = False) -> GBuffers:
    """Background everywhere: what a photo whose object projects outside the frame gets."""
    return GBuffers(uv=np.full((height, width, 2), np.nan) if uv else None,
        normal=np.zeros((height, width, 3)), position=np.zeros((height, width, 3)),
        visibility=np.zeros((height, width)),
        region=np.full((height, width), -1, dtype=np.int32),
        mask=np.zeros((height, width), dtype=bool), camera_center=center,
        orthographic=ortho, window=window)


def decode(channels, *, light, slots, center, ortho, window, uv: bool = False) -> GBuffers:
    """The :class:`GBuffers` of one render from its EXR ``channels``
    (``core.capture.photo_io.read_multilayer_exr``). light: (3,) unit world
    direction towards the light. slots: the number of material slots (region ids
    past the last clamp to it), or None for face sets. center, ortho, window: as in
    :class:`GBuffers`. uv: decode the UV AOV too."""
    def read(pass_name, components):
        try:
            planes = [channels[f"{LAYER}.{pass_name}.{c}"] for c in components]
        except KeyError as missing:
            raise RuntimeError(f"the G-buffer EXR has no channel {missing}; "
                               f"it has {sorted(channels)}") from None
        return np.stack(planes, axis=-1).astype(np.float64)

    with np.errstate(invalid="ignore", divide="ignore", over="ignore"):
        coverage = read("Combined", "A")[..., 0]
        # Passes average over all samples of a pixel, background ones giving 0:
        # divide by the coverage to get the value on the object.
        scale = np.where(coverage > 0.0, 1.0 / coverage, 0.0)[..., None]
        normal = read("Normal", "XYZ") * scale
        position = read("Position", "XYZ") * scale
        direct = read("Diffuse Direct", "RGB").mean(axis=-1) * scale[..., 0]
        region_value = read(REGION_AOV, "X")[..., 0] * scale[..., 0]
        length = np.linalg.norm(normal, axis=-1)
        mask = ((coverage >= 0.5) & np.isfinite(coverage) & np.isfinite(length)
                & (length > 0.5) & np.all(np.isfinite(position), axis=-1)
                & np.isfinite(direct) & np.isfinite(region_value))
        normal = np.where(mask[..., None], normal / np.where(mask, length, 1.0)[..., None], 0.0)
        position = np.where(mask[..., None], position, 0.0)
        cosine = normal @ light
        lit = mask & (cosine > MIN_COSINE)
        visibility = np.where(lit, np.clip(direct / np.where(lit, cosine, 1.0), 0.0, 1.0), 0.0)
        region_value = np.rint(np.where(mask, region_value, 0.0))
        if slots is not None:  # a face whose index is past the last slot renders with it
            region_value = np.clip(region_value, 0, max(slots - 1, 0))
        region = np.where(mask, region_value, -1)
        uv_map = None
        if uv:
            uv_map = read(UV_AOV, "RG") * scale
            uv_map = np.where(mask[..., None] & np.isfinite(uv_map), uv_map, np.nan)
    return GBuffers(normal=normal, position=position, visibility=visibility,
                    region=region.astype(np.int32), mask=mask, camera_center=center,
                    orthographic=ortho, window=window, uv=uv_map)


def footprint_normals(fine: GBuffers, factor: int) -> np.ndarray:
    """The scan's normals over each photo pixel's area, from ``fine``: G-buffers of the
    same camera rendered at ``factor`` x the photo's width and height (each photo pixel
    covers factor x factor fine pixels, whose centres spread evenly over it).

    Returns (H, W, factor**2, 3) float64, world space, unit; the sub-points in row-major
    order within the pixel; NaN where the fine pixel misses the object. This is
    ``pipeline.PhotoInput.footprint_normal``. ValueError (one sentence) for a factor
    below 1 or a fine size that is not a multiple of it.
    """
    if int(factor) != factor or factor < 1:
        raise ValueError(f"the footprint factor must be a positive integer, got {factor}")
    factor = int(factor)
    rows, cols = fine.shape
    if rows % factor or cols % factor:
        raise ValueError(f"fine G-buffers of {cols} x {rows} pixels are not {factor} x a "
                         "photo's size")
    normal = np.where(fine.mask[..., None], fine.normal, np.nan)
    normal = normal.reshape(rows // factor, factor, cols // factor, factor, 3)
    return normal.transpose(0, 2, 1, 3, 4).reshape(rows // factor, cols // factor,
                                                    factor * factor, 3)
