"""Reading photos and masks as linear float arrays (OpenImageIO, no bpy).

Two entries read a photo:

- ``read_photo_file(path, color_space, white_level) -> Photo``: the photo as
  the camera produced it: scene-linear radiance, which pixels were clipped at
  the white level (found on the file's own code values, before decoding),
  which encoding was assumed and why, and the file's metadata (EXIF exposure,
  date, GPS, orientation) for the modules that need them.
- ``read_photo(path, linear=None) -> (H, W, 3) float64``: the older, lenient
  entry (float = linear, any integer format = sRGB, or forced by ``linear``).

``read_metadata(path)`` gives the metadata alone (no pixels), ``read_mask``
a (H, W) bool mask, ``check_finite`` rejects NaN/Inf inside a mask. A value
beyond a half EXR's range (65504) is stored as Inf, so it is refused there;
finite values no camera records (a 1e30 in a float EXR), black photos and
photos at odds with their light are ``core.capture.photo_checks``'.

The AUTO encoding rules of ``read_photo_file`` (the product spec):

- float files (EXR, float TIFF, HDR, PFM, ...) are scene-linear;
- 16/32-bit integer TIFF (and 16-bit PNM, what ``dcraw -4`` writes) are
  scene-linear: that is how RAW converters export linear data;
- 8/16-bit PNG, JPEG, 8-bit TIFF and every other integer format are sRGB and
  are decoded to linear with the IEC 61966-2-1 transfer function,
- unless the file itself says it is linear: OpenImageIO's ``oiio:ColorSpace``
  naming a linear space (``Linear``, ``linear``, ``lin_srgb``, ``lin_rec709``,
  ``scene_linear``, ``Linear Rec.709``, ``ACEScg``, ``ACES2065-1``, ...; see
  ``declared_linear``) or ``oiio:Gamma`` equal to 1.0. What OpenImageIO 3.0
  reports: a PNG whose gAMA chunk is 1.0 reads as ``oiio:ColorSpace`` =
  ``lin_srgb`` (no ``oiio:Gamma``); a PNG written by OpenImageIO with
  ``oiio:ColorSpace`` set keeps that name in a tEXt chunk and reads it back;
  a gAMA of 1/2.2 reads as ``g22_rec709`` with ``oiio:Gamma`` 2.2 (treated as
  sRGB, the nearest encoding this product knows). JPEG and TIFF do not carry
  the attribute through OpenImageIO (a TIFF with an EXIF block always reads
  back ``oiio:ColorSpace`` = ``sRGB``, from the EXIF ColorSpace tag), so a
  file saying sRGB never overrides the rules above; only "linear" does.

Camera RAW goes through OpenImageIO's LibRaw plugin when the build has one
(``raw_supported()``; the PyPI wheel and Blender 5.0's build do not), asked
for linear sRGB-primaries output; otherwise it is a ValueError telling the
user how to convert the file.

Grey images are repeated to RGB; alpha is dropped (read unassociated, so the
colour channels are the file's own codes). Pixels are in file order, row 0 =
top; the EXIF orientation is reported in ``Photo.metadata["Orientation"]``,
not applied. NaN/Inf stay in the arrays: the observations step excludes and
counts them, and ``check_finite`` rejects them where they must not be.

Every user-caused problem (missing, unreadable, truncated or corrupt file,
unsupported RAW, an 8-bit file declared linear) is a ValueError with one
sentence naming the file.

OpenImageIO ships with Blender (and is a pinned dependency for tests); it is
imported on first use so ``import brdf_reconstruct.core`` stays light.
"""

from __future__ import annotations

import os
import re
from dataclasses import dataclass

import numpy as np

#: File extensions of camera RAW formats (lower case, with the dot).
RAW_EXTENSIONS = frozenset({
    ".3fr", ".ari", ".arw", ".bay", ".cap", ".cr2", ".cr3", ".crw", ".dcr", ".dcs",
    ".dng", ".drf", ".eip", ".erf", ".fff", ".iiq", ".k25", ".kdc", ".mdc", ".mef",
    ".mos", ".mrw", ".nef", ".nrw", ".orf", ".pef", ".ptx", ".pxn", ".r3d", ".raf",
    ".raw", ".rw2", ".rwl", ".rwz", ".sr2", ".srf", ".srw", ".x3f",
})

#: The colour-space choices of ``read_photo_file`` (compared case-insensitively).
COLOR_SPACES = ("AUTO", "SRGB", "LINEAR")

#: LibRaw settings asked of OpenImageIO for camera RAW: linear response with
#: sRGB/Rec.709 primaries, AHD demosaic, the camera's white balance, no
#: automatic brightening and clipped highlights, so the output is proportional
#: to the sensor's exposure and its largest code (65535) is the white level.
RAW_CONFIG = {
    "raw:ColorSpace": "sRGB-linear",
    "raw:Demosaic": "AHD",
    "raw:use_camera_wb": 1,
    "raw:auto_bright": 0,
    "raw:HighlightMode": 0,
}

_FORMAT_NAMES = {"openexr": "EXR", "tiff": "TIFF", "png": "PNG", "jpeg": "JPEG",
                 "hdr": "HDR", "pnm": "PNM", "raw": "RAW"}
_LINEAR_HIGH_BIT_FORMATS = ("tiff", "pnm")
_LINEAR_NAMES = {"acescg", "aces2065-1", "aces2065_1", "aces", "scene_linear"}


@dataclass(frozen=True, eq=False)
class Photo:
    """One photo as read from its file.

    radiance: (H, W, 3) float64 scene-linear radiance in the file's units
        (sRGB decoded where applicable; integer codes are scaled so the
        largest code is 1.0); NaN/Inf left in place; row 0 = top.
    saturated: (H, W) bool, True where any colour channel is at or above the
        white level (for integer files: on the file's code values, before
        decoding; plus ``radiance >= white_level`` if the caller gave one).
    encoding: "linear" or "srgb", what was assumed for the file.
    encoding_reason: short text saying why (e.g. "8-bit PNG is sRGB").
    file_format: OpenImageIO's format name ("openexr", "tiff", "png", "jpeg", ...).
    bit_depth: bits per channel of the pixel data (8, 16, 32; half = 16).
    is_float: True for float or half pixel data.
    white_level: the saturation level in the units of ``radiance``: 1.0 for
        integer files (or the caller's lower level), None for float files
        unless the caller passed one.
    metadata: the file's attributes, name -> python value (str, int, float,
        or tuple for arrays), e.g. "ExposureTime" (s, float), "FNumber"
        (float), "Exif:PhotographicSensitivity" (ISO, int),
        "Exif:DateTimeOriginal" (str "YYYY:MM:DD HH:MM:SS"), "GPS:Latitude"
        (tuple of 3 floats: degrees, minutes, seconds), "GPS:LatitudeRef"
        ("N"/"S"), "Orientation" (int, EXIF 1..8), "oiio:ColorSpace" (str).
    nonfinite: number of pixels with a NaN or Inf colour channel.
    covered: (H, W) bool, True where the file holds the pixel, or None where it
        holds the whole frame. An EXR may store only part of its frame (its data
        window, e.g. a render cropped to a region) or more than it (overscan);
        ``radiance`` is always the frame (the display window), 0 where the file
        holds nothing.
    layer: the layer the colour was read from when the file names its channels by
        layer (e.g. ``"ViewLayer.Combined"`` of a Blender multilayer EXR), else None
        (:func:`colour_channels`).
    plateau: (3,) float64, per channel the largest value of a float file where
        that value is a plateau (:func:`plateau_levels`: a highlight clipped at a
        white level the file does not state), NaN where the channel has none; None
        where not looked for (integer files, a white level given, or not asked).
        Pixels at a plateau are ``saturated``, as an integer file's at its largest
        code: at the file's own white level.
    """

    radiance: np.ndarray
    saturated: np.ndarray
    encoding: str
    encoding_reason: str
    file_format: str
    bit_depth: int
    is_float: bool
    white_level: float | None
    metadata: dict
    nonfinite: int
    covered: np.ndarray | None = None
    layer: str | None = None
    plateau: np.ndarray | None = None


#: A float file's largest value in a channel is taken for a white level where at
#: least PLATEAU_PIXELS pixels hold exactly it and at least as many as hold any value
#: within PLATEAU_BAND below it (relative): a clipped highlight piles up at its white
#: level, while a float render or a merged HDR holds its largest value in one pixel
#: or a few among many just below (a half EXR's 10-bit mantissa puts about 20 codes
#: in a 2 % band).
PLATEAU_PIXELS = 8
PLATEAU_BAND = 0.02


def plateau_levels(values: np.ndarray) -> np.ndarray:
    """Per channel, the largest value of ``values`` where it is a plateau (a white
    level; see :data:`PLATEAU_PIXELS`), else NaN.

    values: (H, W, 3) float linear values; non-finite ones are ignored. Returns
    (3,) float64."""
    out = np.full(3, np.nan)
    for c in range(3):
        v = values[..., c]
        v = v[np.isfinite(v) & (v > 0.0)]
        if len(v) < PLATEAU_PIXELS:
            continue
        top = float(np.max(v))
        at = int(np.count_nonzero(v == top))
        below = int(np.count_nonzero((v < top) & (v >= top * (1.0 - PLATEAU_BAND))))
        if at >= PLATEAU_PIXELS and at >= below:
            out[c] = top
    return out


@dataclass(frozen=True)
class _Pixels:
    """A file's colour channels as stored: (H, W, 3) codes of the file's own dtype."""

    codes: np.ndarray
    file_format: str
    is_float: bool
    bit_depth: int
    metadata: dict
    is_raw: bool
    covered: np.ndarray | None = None  # (H, W) bool; None: the file holds the whole frame
    layer: str | None = None  # the named layer the colour was read from (colour_channels)


def srgb_to_linear(x: np.ndarray) -> np.ndarray:
    """IEC 61966-2-1 sRGB decoding (any shape, float64 out).

    Meant for values in [0, 1]; below 0.04045 (negatives included) the linear
    segment x / 12.92 applies, above 1 the power law continues; NaN stays NaN.
    """
    x = np.asarray(x, dtype=np.float64)
    power = ((np.maximum(x, 0.04045) + 0.055) / 1.055) ** 2.4
    return np.where(x <= 0.04045, x / 12.92, power)


def raw_supported() -> bool:
    """True when this OpenImageIO build reads camera RAW (has the LibRaw plugin)."""
    import OpenImageIO as oiio

    return "raw" in oiio.get_string_attribute("format_list").split(",")


def declared_linear(metadata: dict) -> str | None:
    """Why a file's own attributes say its values are linear, or None.

    metadata: name -> value as in ``Photo.metadata``. Honoured:
    ``oiio:ColorSpace`` naming a linear space (a name whose first word is
    "lin"/"linear", that contains the word "linear" without "non", or is
    ACEScg / ACES2065-1 / scene_linear), and ``oiio:Gamma`` == 1.0 (within
    1e-3). Returns e.g. "file says linear (oiio:ColorSpace=Linear)".
    """
    space = metadata.get("oiio:ColorSpace")
    if isinstance(space, str) and space.strip():
        words = [w for w in re.split(r"[^a-z0-9]+", space.strip().lower()) if w]
        name = space.strip().lower().replace(" ", "_")
        if words and "non" not in words and (
            words[0] in ("lin", "linear") or "linear" in words or name in _LINEAR_NAMES
        ):
            return f"file says linear (oiio:ColorSpace={space.strip()})"
    gamma = metadata.get("oiio:Gamma")
    if isinstance(gamma, (int, float)) and abs(float(gamma) - 1.0) < 1e-3:
        return "file says linear (oiio:Gamma=1.0)"
    return None


def read_photo_file(path, color_space: str = "AUTO",
                    white_level: float | None = None, find_clipping: bool = False) -> Photo:
    """Read a photo as scene-linear radiance with its saturation mask and metadata.

    path: the image file (str or path-like).
    color_space: "AUTO" (the rules in the module docstring), "SRGB" (decode
        with the sRGB transfer function) or "LINEAR" (take the values as
        they are), case-insensitive. "LINEAR" on an 8-bit file is refused
        unless the file itself says it is linear.
    white_level: optional saturation level in linear radiance units (the
        units of ``Photo.radiance``); pixels with any channel >= it are
        saturated. Integer files are also saturated where any channel holds
        the largest code.
    find_clipping: for a float file without ``white_level``, look for a channel
        whose largest value the pixels pile up at, as at a white level
        (:func:`plateau_levels`; ``Photo.plateau``); the pixels there are
        ``saturated``.

    Raises ValueError (one sentence naming the file) for a missing,
    unreadable, truncated or corrupt file, a camera RAW file this build
    cannot decode, an 8-bit file declared linear, or a bad argument.
    """
    name = os.fspath(path)
    space = str(color_space).strip().upper()
    if space not in COLOR_SPACES:
        raise ValueError(f"color space for photo {name} must be AUTO, SRGB or LINEAR, "
                         f"not {color_space!r}")
    if white_level is not None:
        white_level = float(white_level)
        if not (np.isfinite(white_level) and white_level > 0.0):
            raise ValueError(f"white level for photo {name} must be a positive finite "
                             f"number, not {white_level}")
    pix = _read_pixels(name)
    encoding, reason = _choose_encoding(pix, space, name)

    if pix.is_float:
        values = pix.codes.astype(np.float64)
        saturated = np.zeros(values.shape[:2], dtype=bool)
        level = white_level
    else:
        top = np.iinfo(pix.codes.dtype).max
        values = pix.codes.astype(np.float64) / float(top)
        saturated = np.any(pix.codes == top, axis=-1)
        level = 1.0 if white_level is None else min(1.0, white_level)
    radiance = values if encoding == "linear" else srgb_to_linear(values)
    if white_level is not None:
        saturated |= np.any(radiance >= white_level, axis=-1)
    plateau = None
    if find_clipping and pix.is_float and white_level is None:
        plateau = plateau_levels(radiance)
        with np.errstate(invalid="ignore"):  # NaN (no plateau) is never reached
            saturated |= np.any(radiance >= plateau, axis=-1)
    nonfinite = int(np.count_nonzero(~np.all(np.isfinite(radiance), axis=-1)))
    return Photo(radiance=radiance, saturated=saturated, encoding=encoding,
                 encoding_reason=reason, file_format=pix.file_format,
                 bit_depth=pix.bit_depth, is_float=pix.is_float, white_level=level,
                 metadata=pix.metadata, nonfinite=nonfinite, covered=pix.covered,
                 layer=pix.layer, plateau=plateau)


def check_finite(photo: Photo | np.ndarray, name: str, mask: np.ndarray | None = None) -> None:
    """Raise ValueError if a pixel inside ``mask`` has a NaN or Inf channel.

    photo: a Photo, or an (H, W, C) / (H, W) array of radiance.
    name: the photo's name for the message (usually its file name).
    mask: optional (H, W) bool, the pixels that matter (all if None).
    """
    values = np.asarray(photo.radiance if isinstance(photo, Photo) else photo)
    bad = ~np.isfinite(values)
    if bad.ndim == 3:
        bad = np.any(bad, axis=-1)
    if mask is not None:
        mask = np.asarray(mask, dtype=bool)
        if mask.shape != bad.shape:
            raise ValueError(f"mask for photo {name} is {mask.shape[1]}x{mask.shape[0]} "
                             f"pixels, but the photo is {bad.shape[1]}x{bad.shape[0]}")
        bad &= mask
    count = int(np.count_nonzero(bad))
    if count:
        pixels = "pixel" if count == 1 else "pixels"
        where = " inside its mask" if mask is not None else ""
        raise ValueError(f"photo {name} has {count} {pixels} with NaN or Inf values{where}; "
                         "fix the file or mask them out")


def read_photo(path, linear: bool | None = None) -> np.ndarray:
    """(H, W, 3) float64 linear radiance of an image file (row 0 = top).

    linear: None decides by the pixel format (float = linear, integer = sRGB;
    camera RAW = linear); True or False forces it (False clips to [0, 1]
    before decoding). Raises ValueError with one sentence for a missing,
    unreadable or truncated file. ``read_photo_file`` is the full reader.
    """
    pix = _read_pixels(os.fspath(path))
    if pix.is_float:
        rgb = pix.codes.astype(np.float64)
    else:
        rgb = pix.codes.astype(np.float64) / float(np.iinfo(pix.codes.dtype).max)
    if linear is None:
        linear = pix.is_float or pix.is_raw
    return rgb if linear else srgb_to_linear(np.clip(rgb, 0.0, 1.0))


def read_mask(path, shape: tuple[int, int] | None = None) -> np.ndarray:
    """(H, W) bool mask: a pixel is used where the image's first channel is > 0.5.

    Integer images are scaled so their largest code is 1.0. shape: the
    photo's (H, W); a different size is a ValueError.
    """
    name = os.fspath(path)
    pix = _read_pixels(name)
    first = pix.codes[..., 0].astype(np.float64)
    if not pix.is_float:
        first /= float(np.iinfo(pix.codes.dtype).max)
    mask = first > 0.5
    if shape is not None and mask.shape != tuple(shape):
        raise ValueError(f"mask {name} is {mask.shape[1]}x{mask.shape[0]} pixels, "
                         f"but its photo is {shape[1]}x{shape[0]}")
    return mask


def read_metadata(path) -> dict:
    """The file's attributes (name -> python value, as ``Photo.metadata``) without
    reading its pixels: EXIF exposure, date, GPS, orientation, ``oiio:*``.

    Raises ValueError (one sentence) for a missing or unreadable file or a
    camera RAW file this build cannot decode.
    """
    name = os.fspath(path)
    is_raw = _check_readable(name)
    inp = _open_input(name, is_raw)
    try:
        return _metadata(inp.spec())
    finally:
        inp.close()


def _choose_encoding(pix: _Pixels, space: str, name: str) -> tuple[str, str]:
    """("linear" | "srgb", reason) for a file under the user's colour-space choice."""
    kind = _FORMAT_NAMES.get(pix.file_format, pix.file_format.upper())
    file_linear = declared_linear(pix.metadata)
    if space == "SRGB":
        return "srgb", "user said sRGB"
    if space == "LINEAR":
        if not pix.is_float and pix.bit_depth <= 8 and file_linear is None:
            raise ValueError(f"photo {name} is 8-bit, which holds sRGB-encoded values, "
                             "not linear radiance; declare it sRGB or export 16-bit/float")
        return "linear", "user said linear"
    if pix.is_raw:
        return "linear", "camera RAW decoded to linear by LibRaw"
    if pix.is_float:
        return "linear", f"float {kind} is scene-linear"
    depth = f"{pix.bit_depth}-bit {kind}"
    if pix.bit_depth >= 16 and pix.file_format in _LINEAR_HIGH_BIT_FORMATS:
        return "linear", f"{depth} is scene-linear"
    if file_linear is not None:
        return "linear", file_linear
    return "srgb", f"{depth} is sRGB"


def _read_pixels(name: str) -> _Pixels:
    """The colour channels and metadata of an image file, checked for read errors."""
    import OpenImageIO as oiio

    is_raw = _check_readable(name)
    inp = _open_input(name, is_raw)
    if not is_raw and inp.format_name() == "raw":
        # A RAW file under an unknown extension: reopen it with the linear settings.
        inp.close()
        is_raw = True
        inp = _open_input(name, is_raw)
    try:
        spec = inp.spec()
        nchannels = spec.nchannels
        # UNKNOWN = the file's own pixel type, so integer codes stay exact.
        pixels = inp.read_image(0, 0, 0, nchannels, oiio.UNKNOWN)
        error = inp.geterror() if inp.has_error else ""
        file_format = inp.format_name()
    finally:
        inp.close()
    if pixels is None or error or np.size(pixels) == 0:
        raise ValueError(f"cannot read image {name}: {_one_line(error) or 'no pixels'}")
    pixels = np.asarray(pixels).reshape(spec.height, spec.width, nchannels)
    rgb, layer = colour_channels(list(spec.channelnames), f"image {name}")
    if rgb is not None:
        codes = pixels[..., rgb]
    elif nchannels >= 3:
        codes = pixels[..., :3]
    else:
        codes = np.repeat(pixels[..., :1], 3, axis=-1)
    is_float = codes.dtype.kind == "f"
    if not is_float and codes.dtype.kind not in "ui":
        raise ValueError(f"cannot read image {name}: unsupported pixel type {spec.format}")
    codes, covered = display_frame(codes, (spec.x, spec.y),
                                   (spec.full_x, spec.full_y, spec.full_width,
                                    spec.full_height))
    if covered is not None and not covered.any():
        raise ValueError(f"image {name} holds no pixel of its frame (its data window "
                         f"{spec.width}x{spec.height} at {spec.x},{spec.y} lies outside "
                         f"its {spec.full_width}x{spec.full_height} display window): "
                         "write the image again")
    return _Pixels(codes=np.ascontiguousarray(codes), file_format=file_format,
                   is_float=is_float, bit_depth=codes.dtype.itemsize * 8,
                   metadata=_metadata(spec), is_raw=is_raw, covered=covered, layer=layer)


# the layer names that hold the image itself, beside passes (Blender's Combined; the
# names other renderers and compositors give their beauty layer), lower case
COLOUR_LAYERS = ("combined", "beauty", "rgba", "rgb", "image", "color", "colour")
_SUFFIXES = {"r": 0, "red": 0, "g": 1, "green": 1, "b": 2, "blue": 2}


def colour_channels(names: list[str], file: str = "the image") -> tuple[list[int] | None,
                                                                         str | None]:
    """Which channels of a file are its colour: (indices of R, G, B, the layer's name
    or None), or (None, None) when no three channels are named so (then the first
    three, or a grey channel, are taken).

    names: the file's channel names in its order, e.g. ``["R", "G", "B", "A"]`` or a
    Blender multilayer EXR's ``["ViewLayer.AO.R", ..., "ViewLayer.Combined.R",
    ...]``. A layer is the part of a name before its last dot; its R, G and B (or
    red, green, blue, any case) are a colour. The unnamed layer wins; else the one
    colour layer; else the one whose last word is in COLOUR_LAYERS (Combined,
    beauty, ...). Several colour layers and none of them the image's: ValueError
    naming them (taking the first, an AO or albedo pass, would be a wrong photo)."""
    layers: dict[str, list[int | None]] = {}
    for index, channel in enumerate(names):
        prefix, _, suffix = channel.rpartition(".")
        slot = _SUFFIXES.get(suffix.lower())
        if slot is not None:
            layers.setdefault(prefix, [None, None, None])[slot] = index
    colour = {prefix: idx for prefix, idx in layers.items() if None not in idx}
    if not colour:
        return None, None
    if "" in colour:
        return colour[""], None
    if len(colour) == 1:
        (prefix, idx), = colour.items()
        return idx, prefix
    image = [p for p in colour if p.rpartition(".")[2].lower() in COLOUR_LAYERS]
    if len(image) == 1:
        return colour[image[0]], image[0]
    shown = ", ".join(sorted(colour)[:6]) + (" and more" if len(colour) > 6 else "")
    raise ValueError(f"{file} holds several colour layers ({shown}) and none is named as "
                     "the image (Combined, beauty): save the photo's own layer alone")


def display_frame(codes: np.ndarray, origin: tuple[int, int],
                  frame: tuple[int, int, int, int]) -> tuple[np.ndarray, np.ndarray | None]:
    """A file's pixels placed in its frame (OpenEXR's display window).

    codes: (h, w, C) pixels of the data window, whose top-left pixel is at
    ``origin`` (x, y), in the file's pixel coordinates (y down). frame: the
    display window (x, y, width, height) in the same coordinates. Returns the
    (height, width, C) frame, 0 where the data window holds nothing, and the (height,
    width) bool mask of what it holds (None when it holds the whole frame, pixels
    outside the frame, overscan, dropped). A frame of no pixels is taken as the
    data window itself."""
    h, w = codes.shape[:2]
    x0, y0 = origin
    fx, fy, fw, fh = frame
    if fw <= 0 or fh <= 0 or (x0, y0, w, h) == (fx, fy, fw, fh):
        return codes, None
    out = np.zeros((fh, fw, codes.shape[2]), dtype=codes.dtype)
    covered = np.zeros((fh, fw), dtype=bool)
    left, top = max(x0, fx), max(y0, fy)
    right, bottom = min(x0 + w, fx + fw), min(y0 + h, fy + fh)
    if right > left and bottom > top:
        out[top - fy:bottom - fy, left - fx:right - fx] = \
            codes[top - y0:bottom - y0, left - x0:right - x0]
        covered[top - fy:bottom - fy, left - fx:right - fx] = True
    return out, (None if covered.all() else covered)


def _check_readable(name: str) -> bool:
    """Whether the file is camera RAW; ValueError if missing or RAW without LibRaw."""
    if not os.path.isfile(name):
        raise ValueError(f"image file not found: {name}")
    is_raw = os.path.splitext(name)[1].lower() in RAW_EXTENSIONS
    if is_raw and not raw_supported():
        raise ValueError(f"camera RAW file {name} cannot be read: this OpenImageIO build "
                         "has no RAW (LibRaw) support; convert it to a 16-bit linear TIFF "
                         "(e.g. dcraw -4 -T, or darktable/RawTherapee with a linear profile)")
    return is_raw


def _open_input(name: str, is_raw: bool):
    """An open oiio.ImageInput (alpha unassociated; LibRaw settings for RAW)."""
    import OpenImageIO as oiio

    config = oiio.ImageSpec()
    config.attribute("oiio:UnassociatedAlpha", 1)
    if is_raw:
        # Only reachable with a LibRaw-enabled build (the tests monkeypatch
        # raw_supported() to reach it; they do not exercise LibRaw itself).
        for key, value in RAW_CONFIG.items():
            config.attribute(key, value)
    oiio.geterror()  # drop a stale global error so a failure below reports its own
    inp = oiio.ImageInput.open(name, config)
    if inp is None:
        raise ValueError(f"cannot read image {name}: "
                         f"{_one_line(oiio.geterror()) or 'unknown format'}")
    return inp


def _metadata(spec) -> dict:
    """name -> python value of every attribute in ``spec.extra_attribs``."""
    out = {}
    for attr in spec.extra_attribs:
        try:
            out[attr.name] = attr.value
        except (TypeError, ValueError, RuntimeError):  # a type Python cannot hold
            continue
    return out


def _one_line(text: str) -> str:
    """The first non-empty line of an OpenImageIO error, without a final period."""
    for line in str(text).splitlines():
        line = line.strip()
        if line:
            return line.rstrip(".")
    return ""


def read_multilayer_exr(path: str | os.PathLike) -> dict[str, np.ndarray]:
    """All channels of an EXR (multi-part, multilayer or plain), by full name: the
    reader of renders (G-buffers, peers' photos) where channel names matter.

    Returns {"ViewLayer.Normal.X": (H, W) float32, ...} on the display window
    (row 0 at the top); pixels outside a part's data window are 0.
    """
    import OpenImageIO as oiio  # ships with Blender and the bpy wheel

    image = oiio.ImageInput.open(os.fspath(path))
    if image is None:
        raise RuntimeError(f"cannot open {path}: {oiio.geterror()}")
    channels = {}
    try:
        part = 0
        while image.seek_subimage(part, 0):
            spec = image.spec()
            data = image.read_image(part, 0, 0, spec.nchannels, oiio.FLOAT)
            if data is None:
                raise RuntimeError(f"cannot read {path}: {image.geterror()}")
            data = np.asarray(data, dtype=np.float32).reshape(
                spec.height, spec.width, spec.nchannels)
            full = np.zeros((spec.full_height, spec.full_width, spec.nchannels), np.float32)
            # Place the data window into the display window (they differ for crops).
            y0, x0 = spec.y - spec.full_y, spec.x - spec.full_x
            ys = slice(max(y0, 0), min(y0 + spec.height, spec.full_height))
            xs = slice(max(x0, 0), min(x0 + spec.width, spec.full_width))
            full[ys, xs] = data[ys.start - y0:ys.stop - y0, xs.start - x0:xs.stop - x0]
            for k, name in enumerate(spec.channelnames):
                channels[name] = full[..., k]
            part += 1
    finally:
        image.close()
    return channels
