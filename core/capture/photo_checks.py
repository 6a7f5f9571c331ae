"""Photos that cannot be right, found before any science (numpy only, no bpy).

Each check takes arrays and either passes, raises ValueError with one sentence
naming the photo and what to do, or (where a user could mean it) returns a
note for the report. The add-on calls them from ``brdf_addon/photo_input.py``:
the size and black checks right after reading a photo, the range, scan and
light checks once the photo's G-buffers exist (on the scan's pixels), so a bad
photo costs seconds.

Units and frames: ``radiance`` is (H, W, 3) float linear radiance in the
file's units (row 0 = top); ``cosine`` is (H, W) n.l of the G-buffer's normal
with the photo's light; ``visibility`` is (H, W) in [0, 1] (0 where n.l <= 0 or
in the scan's cast shadow); ``region`` is (H, W) int (negative = background);
masks are (H, W) bool. A pixel's intensity is the mean of its three channels.

The thresholds, and why:

- ``MIN_SIDE_PX`` = 4: Blender renders nothing smaller than 4 pixels a side, so a
  smaller photo cannot get G-buffers of its own size.
- ``MAX_RANGE`` = 2**32 (32 stops) above the photo's median non-zero magnitude:
  a camera sensor records about 14 stops and a bracketed HDR merge some 20; the
  sun itself is about 20 stops above the median of an outdoor scene, and no lit
  surface is brighter than its light. A value beyond that is not radiance (a
  1e30 in a float EXR beside 0.1-level pixels), and it would dominate every fit.
  Integer files (0..1) and half EXR (up to 65504, beyond is Inf, refused as
  non-finite) cannot reach it unless the rest of the photo is near 0.
- Light consistency (:func:`light_consistency`), per region (one BRDF each): a
  pixel in shadow of the given light gets only indirect light, a lit pixel of
  the same region the direct light as well, so the brightest shadowed pixels
  are darker than the brightest lit ones (the highlight, or the diffuse side
  facing the light). Brighter (``REFUSE_RATIO`` = 1): the light is not where the
  G-buffer puts it (the opposite light, a wrong camera), refused. Under the sun
  a clear sky gives a tenth to a third of the sun's irradiance (the tiny scene
  with a grey world of 0.15 measures 0.13), so above ``NOTE_RATIO`` = 1/2 much
  of the light is unexplained (the light off by tens of degrees, an overcast
  sky, a second lamp): a note. Shadowed pixels within ``EDGE_PX`` = 1 of a lit
  pixel are left out: the pixel filter, a pixel of camera or mesh
  misregistration and the penumbra (at most half lit inside the G-buffer's hard
  shadow) blur the shadow's edge.
- Dark where lit: a pixel facing the light within 60 degrees (n.l >= 1/2,
  unshadowed) gets at least half the irradiance of the region's brightest
  pixels, so with a diffuse part it is at least about half as bright as the
  upper quartile of such pixels; one darker than a tenth of it
  (``DARK_WHERE_LIT``) says the light is elsewhere. A region whose upper
  quartile is itself under a tenth of its brightest lit pixels is all highlight
  (a polished metal, dark off its highlight) and is not judged. More than a
  quarter (``DARK_NOTE_FRACTION``) dark is a note, never a refusal: a user could
  mean it (a dark pattern on a region taken for one BRDF).
- Negative values (:func:`negative_note`): a camera's noise about its black level
  leaves pixels a little below 0, and they are read as they are; one below
  ``NEGATIVE_NOTE`` = 1/4 of the median magnitude of the scan's pixels is more than
  such noise (a wrong black level, a processing step): a note, not a refusal.
- Statistics over fewer than ``MIN_PIXELS`` = 16 pixels say nothing.
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np

MIN_SIDE_PX = 4
MAX_RANGE = 2.0 ** 32
EDGE_PX = 1
MIN_PIXELS = 16
K_LIT = 3
REFUSE_RATIO = 1.0
NOTE_RATIO = 0.5
WELL_LIT_COSINE = 0.5
DARK_WHERE_LIT = 0.1
DARK_NOTE_FRACTION = 0.25
NEGATIVE_NOTE = 0.25


def check_photo_size(name: str, size, camera_name: str, camera_size, source: str) -> None:
    """ValueError (one sentence) when a photo is smaller than ``MIN_SIDE_PX`` on a side.

    size, camera_size: (width, height) in pixels of the photo and of its camera's
    images; source: where the camera's size came from ("camera", "scene render size").
    """
    (w, h), (cw, ch) = size, camera_size
    if min(w, h) < MIN_SIDE_PX:
        raise ValueError(f"photo {name} is only {w}x{h} pixels, but its camera {camera_name} "
                         f"takes {cw}x{ch} ({source}): give the photo at its camera's size "
                         f"(or scaled, at least {MIN_SIDE_PX} pixels a side)")


def _intensity(radiance: np.ndarray) -> np.ndarray:
    """(H, W) mean of the three channels."""
    return np.asarray(radiance, dtype=np.float64).mean(axis=-1)


def _where(mask) -> str:
    return " inside its mask" if mask is not None else ""


def _checked(radiance: np.ndarray, mask) -> np.ndarray:
    """The finite (N, 3) pixels of ``radiance`` inside ``mask`` (all if None)."""
    values = np.asarray(radiance, dtype=np.float64).reshape(-1, 3)
    keep = np.all(np.isfinite(values), axis=-1)
    if mask is not None:
        keep &= np.asarray(mask, dtype=bool).reshape(-1)
    return values[keep]


def _magnitudes(values: np.ndarray) -> tuple[np.ndarray, float | None]:
    """Each pixel's largest channel magnitude (N,) of ``values`` (N, 3), and their
    median over the non-zero ones (None where every pixel is 0): a photo's level."""
    magnitude = np.abs(values).max(axis=-1, initial=0.0)
    nonzero = magnitude[magnitude > 0]
    return magnitude, (float(np.median(nonzero)) if nonzero.size else None)


def check_not_black(radiance: np.ndarray, name: str, mask: np.ndarray | None = None) -> None:
    """ValueError (one sentence) when no finite pixel (inside ``mask``) is above 0.

    radiance: (H, W, 3) linear radiance; mask: optional (H, W) bool.
    """
    values = _checked(radiance, mask)
    if not np.any(values > 0):
        raise ValueError(f"photo {name} is black{_where(mask)} (no pixel above 0): check "
                         "the file, its exposure and that it is the lit photo")


def check_range(radiance: np.ndarray, name: str, mask: np.ndarray | None = None,
                where: str | None = None) -> None:
    """ValueError (one sentence) when pixels (inside ``mask``) are more than
    ``MAX_RANGE`` times the median non-zero magnitude there, in either sign.

    radiance: (H, W, 3) linear radiance (NaN/Inf are ignored here: see
    ``photo_io.check_finite``); mask: optional (H, W) bool; where: the words for
    the mask in the sentence (default " inside its mask"). The add-on checks the
    scan's pixels the run reads: over a whole frame, a black background's float
    dust (1e-17 from a resampled EXR) is the median of its non-zero pixels, and
    every lit pixel would be 2^32 times it.
    """
    magnitude, level = _magnitudes(_checked(radiance, mask))
    if level is None:
        return
    beyond = magnitude > MAX_RANGE * level
    count = int(np.count_nonzero(beyond))
    if count:
        pixels = "pixel" if count == 1 else "pixels"
        place = _where(mask) if where is None else where
        raise ValueError(f"photo {name} has {count} {pixels}{place} more than 2^32 "
                         f"times its median value {level:.3g} (up to "
                         f"{magnitude[beyond].max():.3g}), which no camera records: fix "
                         "the file or mask them out")


def negative_note(radiance: np.ndarray, name: str, mask: np.ndarray | None = None
                  ) -> str | None:
    """A note (one sentence) when a finite pixel (inside ``mask``) has a channel below
    ``-NEGATIVE_NOTE`` times the median magnitude there, None otherwise.

    No light gives negative radiance, but a camera's noise about its black level
    does (a raw file with the black level taken off, a denoised EXR), a little below
    0, and it averages out: so negative values are read as they are. One as large as
    a good share of the scan's typical pixel is not that noise (a wrong black level,
    a processing step), so the user is told.

    radiance: (H, W, 3) linear radiance (NaN/Inf ignored); mask: optional (H, W)
    bool, the scan's pixels the run uses.
    """
    values = _checked(radiance, mask)
    level = _magnitudes(values)[1]
    if level is None:
        return None
    below = np.any(values < -NEGATIVE_NOTE * level, axis=-1)
    count = int(np.count_nonzero(below))
    if not count:
        return None
    pixels = "pixel has" if count == 1 else "pixels have"
    return (f"photo {name}: {count} {pixels} a channel below 0 by more than "
            f"noise about a black level would (down to {values[below].min():.3g}, the "
            f"median pixel {level:.3g}), which no light gives; they are read as they are, "
            "but check the file's black level and processing")


def check_scan_not_black(radiance: np.ndarray, name: str, scan: np.ndarray) -> None:
    """ValueError (one sentence) when every usable pixel of the scan is 0 or less.

    radiance: (H, W, 3); scan: (H, W) bool, the scan's pixels in the photo that
    the run would use (the G-buffer's mask and the user's, silhouette margin).
    """
    values = _checked(radiance, scan)
    if len(values) and not np.any(values > 0):
        raise ValueError(f"photo {name} is black over the scan (all {len(values)} of its "
                         "pixels are 0): check the photo's camera and its exposure")


@dataclasses.dataclass(frozen=True)
class LightConsistency:
    """How a photo's brightness agrees with its G-buffer's light.

    shadow_pixels, lit_pixels: usable pixels counted in the G-buffer's shadow
        (visibility < 1/2, away from the edges, see :func:`light_consistency`)
        and in its light. shadow_to_lit: in the worst region, the brightness of
        its brightest shadowed pixels over that of its brightest lit ones
        (``math.inf`` when the lit ones are all 0 and the shadowed are not), or
        None where no region has ``MIN_PIXELS`` of each. brighter_in_shadow:
        shadowed pixels brighter than their region's brightest lit ones.
    well_lit_pixels: unshadowed pixels with n.l >= ``WELL_LIT_COSINE``.
        dark_where_lit: the fraction of them below ``DARK_WHERE_LIT`` times their
        region's upper quartile of those pixels, over the regions with a diffuse
        part (module docstring), or None (too few, or none judged).
    """

    shadow_pixels: int
    lit_pixels: int
    shadow_to_lit: float | None
    brighter_in_shadow: int
    well_lit_pixels: int
    dark_where_lit: float | None

    def as_dict(self) -> dict:
        """JSON-friendly (an infinite ratio is the string "inf")."""
        out = dataclasses.asdict(self)
        if out["shadow_to_lit"] is not None and not np.isfinite(out["shadow_to_lit"]):
            out["shadow_to_lit"] = "inf"
        return out


def _near(mask: np.ndarray, radius: int = 1) -> np.ndarray:
    """(H, W) bool: pixels within ``radius`` (chessboard distance) of a True of ``mask``."""
    h, w = mask.shape
    padded = np.pad(mask, radius)
    out = np.zeros_like(mask)
    for dy in range(2 * radius + 1):  # (2r+1)^2 shifted views, each vectorised
        for dx in range(2 * radius + 1):
            out |= padded[dy:dy + h, dx:dx + w]
    return out


def _kth_largest(values: np.ndarray, k: int) -> float:
    """The k-th largest of a 1-D array (its smallest when it has fewer than k)."""
    k = min(k, values.size)
    return float(np.partition(values, values.size - k)[values.size - k])


def light_consistency(radiance: np.ndarray, cosine: np.ndarray, visibility: np.ndarray,
                      region: np.ndarray, usable: np.ndarray) -> LightConsistency:
    """Whether the photo is brighter where its G-buffer says shadow than where it says
    light, and whether it is dark where the G-buffer lights it fully.

    radiance (H, W, 3), cosine, visibility, region (H, W) as in the module
    docstring; usable: (H, W) bool, the scan's pixels the run would use (G-buffer
    mask, the user's mask and silhouette margin). Saturated pixels count (their
    value is a lower bound of a bright pixel). Per region (one BRDF each): the
    lit pixels' brightness is their ``K_LIT``-th largest intensity (the highlight
    if any; a hot pixel among them only makes the test milder), the shadowed
    pixels' the ``max(3, n / 10^4)``-th largest (hot pixels do not count).
    Shadowed pixels within ``EDGE_PX`` of a lit pixel are left out (penumbra, the
    pixel filter, a pixel of misregistration), and those within ``EDGE_PX`` of
    the background too unless fewer than ``MIN_PIXELS`` would remain.
    """
    y = _intensity(radiance)
    region = np.asarray(region)
    cosine = np.asarray(cosine, dtype=np.float64)
    visibility = np.asarray(visibility, dtype=np.float64)
    scan = np.asarray(usable, dtype=bool) & np.isfinite(y) & (region >= 0)
    lit_any = (visibility >= 0.5) & (cosine > 0) & (region >= 0)
    lit = scan & lit_any
    shadow = scan & (visibility < 0.5) & ~_near(lit_any, EDGE_PX)
    inner = shadow & ~_near(region < 0, EDGE_PX)
    if np.count_nonzero(inner) >= MIN_PIXELS:
        shadow = inner
    well = lit & (cosine >= WELL_LIT_COSINE)

    worst, brighter = None, 0
    dark_count = well_count = 0
    for r in np.unique(region[scan]):  # one pass per region (a handful), not per pixel
        in_r = region == r
        ys, yl, yw = y[shadow & in_r], y[lit & in_r], y[well & in_r]
        if ys.size >= MIN_PIXELS and yl.size >= MIN_PIXELS:
            top_lit = _kth_largest(yl, K_LIT)
            top_shadow = _kth_largest(ys, max(3, -(-ys.size // 10_000)))
            if top_shadow <= 0:
                ratio = 0.0
            else:
                ratio = top_shadow / top_lit if top_lit > 0 else math.inf
            worst = ratio if worst is None else max(worst, ratio)
            brighter += int(np.count_nonzero(ys > top_lit))
        if yw.size >= MIN_PIXELS:
            quartile = float(np.quantile(yw, 0.75))
            # judged only with a diffuse part: the upper quartile within a factor
            # 1 / DARK_WHERE_LIT of the brightest (a polished metal is all highlight)
            if quartile > 0 and quartile >= DARK_WHERE_LIT * _kth_largest(yl, K_LIT):
                dark_count += int(np.count_nonzero(yw < DARK_WHERE_LIT * quartile))
                well_count += yw.size
    return LightConsistency(
        shadow_pixels=int(np.count_nonzero(shadow)), lit_pixels=int(np.count_nonzero(lit)),
        shadow_to_lit=worst, brighter_in_shadow=brighter,
        well_lit_pixels=int(np.count_nonzero(well)),
        dark_where_lit=dark_count / well_count if well_count else None)


def check_light(consistency: LightConsistency, name: str) -> list[str]:
    """Notes (sentences without the photo's name) for a partly inconsistent photo;
    ValueError (one sentence naming the photo) when its shadow is brighter than its
    light (``shadow_to_lit`` > ``REFUSE_RATIO``)."""
    c = consistency
    notes = []
    if c.shadow_to_lit is not None and c.shadow_to_lit > REFUSE_RATIO:
        raise ValueError(f"photo {name} is brighter where its G-buffer puts the scan in shadow "
                         f"than where it lights it ({c.brighter_in_shadow} of those "
                         f"{c.shadow_pixels} shadowed pixels are brighter than its brightest "
                         "lit ones): check the photo's light (direction, Sun object or sun "
                         "position) and its camera")
    if c.shadow_to_lit is not None and c.shadow_to_lit > NOTE_RATIO:
        notes.append(f"the brightest of the {c.shadow_pixels} pixels its G-buffer puts in "
                     f"shadow are {c.shadow_to_lit:.0%} as bright as its brightest lit ones "
                     "(a clear sky gives under a third); check its light and camera")
    if c.dark_where_lit is not None and c.dark_where_lit > DARK_NOTE_FRACTION:
        notes.append(f"{c.dark_where_lit:.0%} of the {c.well_lit_pixels} pixels its G-buffer "
                     "lights fully are dark (under a tenth of the brightest quarter of them); "
                     "unless the surface is a polished metal, check its light and camera")
    return notes
