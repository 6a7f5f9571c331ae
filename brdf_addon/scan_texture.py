"""The scan's own colour texture, read as the albedo prior of a textured run (issue 16).

A photogrammetry mesh arrives with a colour texture baked from the ambient
photos. Its colour follows the albedo up to the ambient light's level and tint,
which ``core.method.albedo.estimate`` fits per channel; where no lit photo sees a
texel it is the only evidence there is.

Which image: in the scan's first material (in slot order) that has one, the
Image Texture feeding a Principled BSDF's Base Color (through any nodes between),
else its first Image Texture node with an image. The image is only read
(``Image.pixels``), never changed, saved or reloaded.

Frames: the prior is (height, width, 3) with row 0 at the top (file order), in
linear colour (an 8/16-bit image in sRGB is decoded; a float or Non-Color one is
taken as it is).
"""

from __future__ import annotations

import numpy as np
from scipy import ndimage

from ..core.capture.photo_io import srgb_to_linear

DEFAULT_SIZE = 512  # texels a side of the albedo image when the scan has no texture


def find_image(obj):
    """The scan's colour texture (``bpy.types.Image``), or None (see the module docstring)."""
    for slot in getattr(obj, "material_slots", ()):
        mat = slot.material
        if mat is None or mat.node_tree is None:
            continue
        nodes = mat.node_tree.nodes
        for node in nodes:
            if node.type == "BSDF_PRINCIPLED" and node.inputs["Base Color"].is_linked:
                image = _upstream_image(node.inputs["Base Color"])
                if image is not None:
                    return image
        for node in nodes:
            if node.type == "TEX_IMAGE" and node.image is not None:
                return node.image
    return None


def _upstream_image(socket, depth: int = 0):
    """The first Image Texture's image found walking links back from ``socket``."""
    if depth > 16:
        return None
    for link in socket.links:
        node = link.from_node
        if node.type == "TEX_IMAGE" and node.image is not None:
            return node.image
        for upstream in node.inputs:
            if upstream.is_linked:
                found = _upstream_image(upstream, depth + 1)
                if found is not None:
                    return found
    return None


def texture_shape(image, size: int) -> tuple[int, int]:
    """(height, width) of the albedo image: ``size`` x ``size`` when size > 0, else the
    scan texture's own size, else DEFAULT_SIZE a side."""
    if size > 0:
        return int(size), int(size)
    if image is not None and image.size[0] > 0 and image.size[1] > 0:
        return int(image.size[1]), int(image.size[0])
    return DEFAULT_SIZE, DEFAULT_SIZE


def read_prior(image, shape) -> np.ndarray:
    """(height, width, 3) float64 linear colour of ``image`` resampled (bilinear) to
    ``shape``, row 0 at the top. ValueError (one sentence) when the image has no
    pixels (a missing file, say) or holds NaN or Inf."""
    width, height = int(image.size[0]), int(image.size[1])
    if width < 1 or height < 1:
        raise ValueError(f"the scan's texture {image.name!r} has no pixels (is its file "
                         "missing?); reconstruct without it, or fix its path")
    channels = int(image.channels)
    pixels = np.empty(width * height * channels, dtype=np.float32)
    image.pixels.foreach_get(pixels)
    rgb = pixels.reshape(height, width, channels)[::-1, :, :3].astype(np.float64)
    if channels < 3:
        rgb = np.repeat(rgb[..., :1], 3, axis=2)
    if not np.isfinite(rgb).all():
        raise ValueError(f"the scan's texture {image.name!r} holds NaN or Inf")
    space = image.colorspace_settings.name
    if not image.is_float and space.lower().startswith("srgb"):
        rgb = srgb_to_linear(np.clip(rgb, 0.0, 1.0))
    if (height, width) != tuple(shape):
        rgb = ndimage.zoom(rgb, (shape[0] / height, shape[1] / width, 1.0), order=1,
                           mode="nearest", grid_mode=True)
    return np.maximum(rgb, 0.0)
