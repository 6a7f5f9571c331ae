"""Result pictures as plain RGB arrays (no plotting library: Blender has none).

- :func:`slice_image`: the table's (theta_h, theta_d) slice at phi_d = 90 deg,
  the standard view of a MERL table, log-scaled.
- :func:`photo_vs_render`: photo and render side by side, same exposure.
- :func:`reliable_overlay`: which pixels the reliable region kept, over a photo.

Images are (H, W, 3) float32 display values in [0, 1] (sRGB-encoded), row 0
at the top; :func:`write_png` saves one with OpenImageIO.
"""

from __future__ import annotations

import os

import numpy as np

from .. import files
from ..brdf import merl


def srgb_encode(x: np.ndarray) -> np.ndarray:
    """Linear [0, 1] -> sRGB-encoded [0, 1] (float32)."""
    x = np.clip(np.asarray(x, dtype=np.float64), 0.0, 1.0)
    return np.where(x <= 0.0031308, 12.92 * x,
                    1.055 * np.power(x, 1 / 2.4) - 0.055).astype(np.float32)


def slice_image(table: np.ndarray, scale: int = 3, decades: float = 4.0) -> np.ndarray:
    """(90*scale, 90*scale, 3) picture of the phi_d = 90 deg slice of ``table``.

    Rows: theta_d from 0 (top) to 90 deg; columns: theta_h from 0 (left) to 90
    deg (the MERL bins, theta_h in its square-root spacing). Each channel is
    log10-scaled over ``decades`` below the slice's maximum; unmeasured cells
    are dark grey.
    """
    s = np.asarray(table, dtype=np.float64)[:, :, :, merl.SHAPE[2] // 2]  # (3, th, td)
    s = np.transpose(s, (2, 1, 0))  # (td, th, 3)
    valid = np.all(np.isfinite(s), axis=-1) & np.all(s >= 0, axis=-1)
    top = np.max(s[valid]) if valid.any() else 1.0
    with np.errstate(divide="ignore"):
        logv = np.log10(np.maximum(np.where(valid[..., None], s, 0.0), 1e-300) / max(top, 1e-300))
    img = np.clip(1.0 + logv / decades, 0.0, 1.0)
    img[~valid] = 0.15
    img = np.repeat(np.repeat(img, scale, axis=0), scale, axis=1)
    return img.astype(np.float32)


def photo_vs_render(photo: np.ndarray, render: np.ndarray, mask: np.ndarray,
                    gap: int = 4) -> np.ndarray:
    """(H, 2W + gap, 3) sRGB picture: photo (left) and render (right), both scaled
    so the photo's 99th percentile inside ``mask`` is white."""
    photo = np.nan_to_num(np.asarray(photo, dtype=np.float64), nan=0.0, posinf=0.0)
    render = np.nan_to_num(np.asarray(render, dtype=np.float64), nan=0.0, posinf=0.0)
    mask = np.asarray(mask, dtype=bool)
    values = photo[mask].max(axis=-1) if mask.any() else np.ones(1)
    white = max(float(np.percentile(values, 99)), 1e-12)
    h, w = mask.shape
    out = np.zeros((h, 2 * w + gap, 3), dtype=np.float32)
    out[:, :w] = srgb_encode(np.where(mask[..., None], photo, 0.0) / white)
    out[:, w + gap:] = srgb_encode(np.where(mask[..., None], render, 0.0) / white)
    return out


def reliable_overlay(photo: np.ndarray, observed_rc: np.ndarray,
                     reliable_rc: np.ndarray) -> np.ndarray:
    """(H, W, 3) sRGB picture of the reliable region over a photo: the photo in
    grey, observed pixels the stages dropped in red, reliable pixels in green.
    observed_rc, reliable_rc: (N, 2) int (row, column)."""
    photo = np.nan_to_num(np.asarray(photo, dtype=np.float64), nan=0.0, posinf=0.0)
    grey = photo.mean(axis=-1)
    white = max(float(np.percentile(grey[grey > 0], 99)) if np.any(grey > 0) else 1.0, 1e-12)
    base = srgb_encode(grey / white)
    out = np.repeat(0.6 * base[..., None], 3, axis=-1)
    for rc, colour in ((observed_rc, (0.9, 0.15, 0.1)), (reliable_rc, (0.1, 0.85, 0.2))):
        rc = np.asarray(rc, dtype=np.int64).reshape(-1, 2)
        out[rc[:, 0], rc[:, 1]] = 0.4 * base[rc[:, 0], rc[:, 1], None] + 0.6 * np.array(colour)
    return out.astype(np.float32)


def write_png(path: str | os.PathLike, image: np.ndarray) -> None:
    """Save an (H, W, 3) [0, 1] picture as an 8-bit PNG (already display-encoded)."""
    import OpenImageIO as oiio

    image = np.ascontiguousarray(np.clip(image, 0.0, 1.0) * 255.0 + 0.5).astype(np.uint8)
    h, w, c = image.shape
    with files.replacing(path) as tmp:  # renamed into place when complete
        out = oiio.ImageOutput.create(str(tmp))
        if out is None or not out.open(str(tmp), oiio.ImageSpec(w, h, c, oiio.UINT8)):
            raise ValueError(f"cannot write {os.fspath(path)}")
        out.write_image(image)
        out.close()
