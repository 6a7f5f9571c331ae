"""Texture files of a textured region (issue 16): the albedo image beside the
``.binary`` table, and the coverage image that says which texels were measured.

- Albedo: a 16-bit PNG, sRGB-encoded as colour textures are (what Blender's Image
  Texture, glTF's base colour and other tools expect), or a float EXR, linear, for
  values above 1 or where 16 bits are not enough. Values are linear reflectance
  in, clipped to [0, 1] for the PNG (the report says how many texels were clipped).
- Coverage: an 8-bit greyscale PNG, 255 measured, 128 inferred from the scan's
  texture, 0 filled (``core.method.albedo.AlbedoMap.coverage_image``).

Every file is written to a temporary name and renamed into place when complete
(``core.files.replacing``). Images have row 0 at the top (file order).
"""

from __future__ import annotations

import os

import numpy as np

from .. import files

FORMATS = ("PNG", "EXR")


def linear_to_srgb(x: np.ndarray) -> np.ndarray:
    """IEC 61966-2-1 sRGB encoding (the inverse of
    ``core.capture.photo_io.srgb_to_linear``), any shape, float64 out; meant for [0, 1]."""
    x = np.asarray(x, dtype=np.float64)
    power = 1.055 * np.maximum(x, 0.0031308) ** (1.0 / 2.4) - 0.055
    return np.where(x <= 0.0031308, 12.92 * x, power)


def write_albedo(path: str | os.PathLike, image: np.ndarray, file_format: str = "PNG") -> int:
    """Write an (H, W, 3) linear albedo image; returns the number of texels clipped
    (any channel outside [0, 1], PNG only). file_format: "PNG" (16-bit, sRGB) or
    "EXR" (float32 linear, written as given). ValueError for NaN or Inf, a bad
    shape or format, or a file that cannot be written."""
    import OpenImageIO as oiio

    image = np.asarray(image, dtype=np.float64)
    if image.ndim != 3 or image.shape[2] != 3:
        raise ValueError(f"an albedo image must have shape (H, W, 3), got {image.shape}")
    if not np.isfinite(image).all():
        raise ValueError("the albedo image holds NaN or Inf")
    if file_format not in FORMATS:
        raise ValueError(f"texture format must be one of {FORMATS}, got {file_format!r}")
    clipped = 0
    if file_format == "PNG":
        clipped = int(np.any((image < 0.0) | (image > 1.0), axis=2).sum())
        data = np.rint(linear_to_srgb(np.clip(image, 0.0, 1.0)) * 65535.0).astype(np.uint16)
        kind = oiio.UINT16
    else:
        data, kind = image.astype(np.float32), oiio.FLOAT
    _write(path, np.ascontiguousarray(data), kind,
           {"oiio:ColorSpace": "srgb_rec709_scene" if file_format == "PNG" else "lin_rec709"})
    return clipped


def write_coverage(path: str | os.PathLike, image: np.ndarray) -> None:
    """Write an (H, W) uint8 coverage image as an 8-bit greyscale PNG."""
    import OpenImageIO as oiio

    image = np.asarray(image)
    if image.ndim != 2 or image.dtype != np.uint8:
        raise ValueError(f"a coverage image must be (H, W) uint8, got {image.dtype} {image.shape}")
    _write(path, np.ascontiguousarray(image[..., None]), oiio.UINT8, {})


def _write(path, data: np.ndarray, kind, attributes: dict) -> None:
    import OpenImageIO as oiio

    h, w, c = data.shape
    with files.replacing(path) as tmp:  # renamed into place when complete
        spec = oiio.ImageSpec(w, h, c, kind)
        for key, value in attributes.items():
            spec.attribute(key, value)
        out = oiio.ImageOutput.create(str(tmp))
        if out is None or not out.open(str(tmp), spec):
            raise ValueError(f"cannot write {os.fspath(path)}")
        out.write_image(data)
        out.close()
