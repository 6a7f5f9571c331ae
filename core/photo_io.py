"""Reading photos and masks as linear float arrays (OpenImageIO, no bpy).

Float formats (EXR, HDR, float TIFF) are taken as scene-linear. Integer
formats (8/16-bit PNG, JPEG, TIFF) are taken as sRGB-encoded and decoded to
linear with the sRGB transfer function, unless ``linear=True``. Grey images
are repeated to RGB; alpha is dropped. NaN/Inf stay in the array: the
observations step excludes and counts them.

OpenImageIO ships with Blender (and is a pinned dependency for tests); it is
imported on first use so ``import brdf_reconstruct.core`` stays light.
"""

from __future__ import annotations

import os

import numpy as np


def srgb_to_linear(x: np.ndarray) -> np.ndarray:
    """IEC 61966-2-1 sRGB decoding of values in [0, 1] (any shape, float64)."""
    x = np.asarray(x, dtype=np.float64)
    return np.where(x <= 0.04045, x / 12.92, ((x + 0.055) / 1.055) ** 2.4)


def _open(path):
    import OpenImageIO as oiio

    path = os.fspath(path)
    if not os.path.isfile(path):
        raise ValueError(f"image file not found: {path}")
    buf = oiio.ImageBuf(path)
    if buf.has_error:
        raise ValueError(f"cannot read image {path}: {buf.geterror().strip()}")
    return buf


def read_photo(path, linear: bool | None = None) -> np.ndarray:
    """(H, W, 3) float64 linear radiance of an image file (row 0 = top).

    linear: None decides by the pixel format (float = linear, integer = sRGB);
    True or False forces it. Raises ValueError with one sentence for a missing
    or unreadable file.
    """
    buf = _open(path)
    spec = buf.spec()
    pixels = buf.get_pixels(_float_format())
    if pixels is None or pixels.size == 0:
        raise ValueError(f"cannot read image {os.fspath(path)}: no pixels")
    pixels = np.asarray(pixels, dtype=np.float64).reshape(spec.height, spec.width,
                                                          spec.nchannels)
    if spec.nchannels >= 3:
        rgb = pixels[..., :3]
    else:
        rgb = np.repeat(pixels[..., :1], 3, axis=-1)
    is_float = spec.format.basetype in _float_basetypes()
    if linear is None:
        linear = is_float
    return rgb if linear else srgb_to_linear(np.clip(rgb, 0.0, 1.0))


def read_mask(path, shape: tuple[int, int] | None = None) -> np.ndarray:
    """(H, W) bool mask: a pixel is used where the image's first channel is > 0.5.

    shape: the photo's (H, W); a different size is a ValueError.
    """
    buf = _open(path)
    spec = buf.spec()
    pixels = np.asarray(buf.get_pixels(_float_format()), dtype=np.float64)
    mask = pixels.reshape(spec.height, spec.width, spec.nchannels)[..., 0] > 0.5
    if shape is not None and mask.shape != tuple(shape):
        raise ValueError(f"mask {os.fspath(path)} is {mask.shape[1]}x{mask.shape[0]} pixels, "
                         f"but its photo is {shape[1]}x{shape[0]}")
    return mask


def _float_format():
    import OpenImageIO as oiio

    return oiio.FLOAT


def _float_basetypes():
    import OpenImageIO as oiio

    return (oiio.FLOAT, oiio.HALF, oiio.DOUBLE)
