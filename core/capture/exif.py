"""Exposure, capture time and place from a photo's metadata (EXIF).

The metadata arrive as a plain dict {attribute name: value}, as OpenImageIO
3.0 reports them in ``ImageSpec.extra_attribs`` (``{p.name: p.value for p in
spec.extra_attribs}``). Names are matched case-insensitively, as OIIO does.
What OIIO 3.0 really produces (checked by round trips in
tests/core/capture/test_exif.py):

- ``ExposureTime`` float (s) and ``FNumber`` float, from EXIF rationals (JPEG
  and TIFF); ``Exif:ShutterSpeedValue`` / ``Exif:ApertureValue`` float APEX
  values (fallbacks: t = 2^-Tv, N = 2^(Av / 2)).
- ISO: JPEG ``Exif:PhotographicSensitivity`` int (uint16; OIIO 3.0 reports
  the old ``Exif:ISOSpeedRatings`` tag under this name, older readers and the
  RAW reader may still say ``Exif:ISOSpeedRatings``). Above 65535 the tag
  holds 65535 and the value is in ``Exif:RecommendedExposureIndex`` or
  ``Exif:ISOSpeed`` (int), which are also what OIIO's TIFF writer keeps.
- ``Exif:DateTimeOriginal`` str "YYYY:MM:DD HH:MM:SS" (local time of the
  camera clock), ``Exif:OffsetTimeOriginal`` str "+HH:MM" (EXIF 2.31),
  ``Exif:SubsecTimeOriginal`` str of digits.
- GPS (JPEG only; OIIO's TIFF writer drops the GPS directory):
  ``GPS:Latitude`` / ``GPS:Longitude`` tuple of 3 floats (degrees, minutes,
  seconds, from rationals), ``GPS:LatitudeRef`` "N"/"S", ``GPS:LongitudeRef``
  "E"/"W", ``GPS:Altitude`` float (m), ``GPS:Status`` "A" (valid) / "V" (void).

Radiometry: a linear pixel value is proportional to radiance * t * S / N^2
(t exposure time in s, S the ISO sensitivity, N the f-number), so the factor
that brings photo i onto the scale of a reference photo is
k_i = (N_i^2 / (t_i S_i)) / (N_ref^2 / (t_ref S_ref)); multiply photo i's
linear pixels by k_i.
"""

from __future__ import annotations

import dataclasses
import datetime as _dt
import math
import re
from typing import NamedTuple

import numpy as np

_ISO_NAMES = (
    "Exif:PhotographicSensitivity",
    "Exif:ISOSpeedRatings",
    "Exif:ISOSpeed",
    "Exif:RecommendedExposureIndex",
    "Exif:StandardOutputSensitivity",
)
_ISO_OVERFLOW = 65535  # a uint16 ISO tag saturates here; the true value is elsewhere
_OFFSET_RE = re.compile(r"^([+-])(\d{2}):(\d{2})$")
_DATETIME_RE = re.compile(r"^(\d{4}):(\d{2}):(\d{2})[ T](\d{2}):(\d{2}):(\d{2})$")


@dataclasses.dataclass(frozen=True)
class Exposure:
    """Camera exposure settings of one photo.

    shutter_s: exposure time in seconds (> 0); f_number: N (> 0); iso: the
    sensitivity S (> 0), as the camera reports it.
    """

    shutter_s: float
    f_number: float
    iso: float

    @property
    def relative_gain(self) -> float:
        """t S / N^2: what a linear pixel value is proportional to, per unit radiance."""
        return self.shutter_s * self.iso / self.f_number**2

    def describe(self) -> str:
        """Human form, e.g. "1/250 s, f/8, ISO 100"."""
        return f"{_format_shutter(self.shutter_s)}, f/{self.f_number:.3g}, ISO {self.iso:.0f}"


class CaptureTime(NamedTuple):
    """When a photo was taken, as `capture_time` found it.

    when: the capture instant. Timezone-aware (tzinfo = the EXIF offset) if
        has_offset, else naive local camera time, which the caller must pair
        with a UTC offset asked from the user (core.capture.sun rejects naive times).
    has_offset: True when the metadata gave the UTC offset.
    """

    when: _dt.datetime
    has_offset: bool


def _lookup(metadata: dict, name: str):
    """Case-insensitive lookup of one attribute (OIIO's names are case-insensitive)."""
    if name in metadata:
        return metadata[name]
    lower = name.lower()
    for key, value in metadata.items():
        if isinstance(key, str) and key.lower() == lower:
            return value
    return None


def _positive(value) -> float | None:
    """A finite positive float from a number or a 1-element sequence, else None."""
    if isinstance(value, list | tuple | np.ndarray):
        flat = np.asarray(value).ravel()
        if flat.size == 0:
            return None
        value = flat[0]
    if isinstance(value, bool | str | bytes) or value is None:
        return None
    try:
        x = float(value)
    except (TypeError, ValueError):
        return None
    return x if math.isfinite(x) and x > 0.0 else None


def _apex(value, scale: float) -> float | None:
    """2^(-value / scale) for an APEX value (finite), else None."""
    if isinstance(value, bool | str | bytes) or value is None:
        return None
    try:
        v = float(value)
    except (TypeError, ValueError):
        return None
    if not math.isfinite(v) or abs(v) > 64.0:
        return None
    return 2.0 ** (-v / scale)


def _iso(metadata: dict) -> float | None:
    values = [_positive(_lookup(metadata, name)) for name in _ISO_NAMES]
    found = [v for v in values if v is not None]
    if not found:
        return None
    if found[0] == _ISO_OVERFLOW and len(found) > 1:
        return found[1]
    return found[0]


def exposure_settings(metadata: dict) -> Exposure | None:
    """The photo's shutter time, f-number and ISO, or None if any is missing or invalid.

    metadata: {OIIO attribute name: value} (see the module docstring for the
    names read). The exposure time comes from ``ExposureTime`` (else APEX
    ``Exif:ShutterSpeedValue``), the f-number from ``FNumber`` (else APEX
    ``Exif:ApertureValue``), ISO from the first valid ISO tag. Each must be
    finite and > 0.
    """
    shutter = _positive(_lookup(metadata, "ExposureTime"))
    if shutter is None:
        shutter = _apex(_lookup(metadata, "Exif:ShutterSpeedValue"), 1.0)
    f_number = _positive(_lookup(metadata, "FNumber"))
    if f_number is None:
        f_number = _apex(_lookup(metadata, "Exif:ApertureValue"), -2.0)
    iso = _iso(metadata)
    if shutter is None or f_number is None or iso is None:
        return None
    return Exposure(shutter_s=shutter, f_number=f_number, iso=iso)


def _format_shutter(t: float) -> str:
    if t < 1.0:
        inverse = 1.0 / t
        if abs(inverse - round(inverse)) < 0.01 * inverse:
            return f"1/{round(inverse)} s"
        return f"{t:.3g} s"
    return f"{t:.3g} s"


def exposure_scales(exposures, user_scales, names=None) -> tuple[np.ndarray, list[str]]:
    """Factors that bring every photo to one radiometric scale, and a note per photo.

    exposures: N entries, `Exposure` or None (from `exposure_settings`).
    user_scales: N entries, a factor the user gave for that photo (finite,
        > 0) or None. A user scale wins over EXIF.
    names: N photo names for the notes and errors (default "photo 1", ...).

    The rule is all-or-nothing for the photos without a user scale:
    - all of them have EXIF: k_i = (N_i^2 / (t_i S_i)) / (N_ref^2 / (t_ref S_ref)),
      the reference being the first of them (its k is 1);
    - none of them has EXIF: k_i = 1, noted "no exposure EXIF: photos assumed
      equally exposed";
    - some have and some do not: ValueError naming the first photo without.
    User scales are factors onto that same common scale (the reference
    photo's raw values, or the raw values when no photo uses EXIF).

    Returns (scales (N,) float64: multiply photo i's linear pixels by
    scales[i]; notes: exactly one line per photo, e.g. "b.jpg: x2 from EXIF
    (1/250 s, f/8, ISO 100 vs 1/125 s, f/8, ISO 100)").
    """
    exposures, user_scales = list(exposures), list(user_scales)
    n = len(exposures)
    if len(user_scales) != n:
        raise ValueError(
            f"user_scales must have one entry per photo ({n}), got {len(user_scales)}"
        )
    names = [f"photo {i + 1}" for i in range(n)] if names is None else list(names)
    if len(names) != n:
        raise ValueError(f"names must have one entry per photo ({n}), got {len(names)}")
    for i, e in enumerate(exposures):
        if e is not None and not isinstance(e, Exposure):
            raise ValueError(f"exposures[{i}] must be an Exposure or None, got {type(e).__name__}")
    user = []
    for i, s in enumerate(user_scales):
        if s is None:
            user.append(None)
            continue
        v = _positive(s) if np.ndim(s) == 0 else None
        if v is None:
            raise ValueError(
                f"the exposure scale of {names[i]} must be a finite number > 0, got {s!r}"
            )
        user.append(v)

    free = [i for i in range(n) if user[i] is None]
    with_exif = [i for i in free if exposures[i] is not None]
    without = [i for i in free if exposures[i] is None]
    if with_exif and without:
        raise ValueError(
            f"{names[without[0]]} has no exposure EXIF (shutter, f-number, ISO) while "
            "other photos do; give its exposure scale"
        )

    scales = np.ones(n, dtype=np.float64)
    notes = []
    ref = with_exif[0] if with_exif else None
    for i in range(n):
        if user[i] is not None:
            scales[i] = user[i]
            notes.append(f"{names[i]}: x{user[i]:.4g} from the user's exposure scale")
        elif ref is None:
            notes.append(f"{names[i]}: x1, no exposure EXIF: photos assumed equally exposed")
        elif i == ref:
            notes.append(f"{names[i]}: x1, exposure reference ({exposures[i].describe()})")
        else:
            scales[i] = exposures[ref].relative_gain / exposures[i].relative_gain
            notes.append(
                f"{names[i]}: x{scales[i]:.4g} from EXIF ({exposures[i].describe()} vs "
                f"{exposures[ref].describe()})"
            )
    return scales, notes


def _clean_string(value) -> str | None:
    if isinstance(value, bytes):
        value = value.decode("ascii", errors="replace")
    if not isinstance(value, str):
        return None
    return value.strip("\x00 \t\r\n")


def _parse_offset(value) -> _dt.timezone | None:
    text = _clean_string(value)
    if not text:
        return None
    m = _OFFSET_RE.match(text)
    if m is None:
        return None
    hours, minutes = int(m.group(2)), int(m.group(3))
    if hours > 14 or minutes >= 60:
        return None
    sign = -1 if m.group(1) == "-" else 1
    return _dt.timezone(sign * _dt.timedelta(hours=hours, minutes=minutes))


def _parse_datetime(value) -> _dt.datetime | None:
    text = _clean_string(value)
    if not text:
        return None
    m = _DATETIME_RE.match(text)
    if m is None:
        return None
    try:
        return _dt.datetime(*(int(g) for g in m.groups()))
    except ValueError:  # "0000:00:00 00:00:00", month 13, ...
        return None


def capture_time(metadata: dict) -> CaptureTime | None:
    """When the photo was taken: `CaptureTime` (when, has_offset), or None if unknown.

    Reads ``Exif:DateTimeOriginal`` (else ``Exif:DateTimeDigitized``) with its
    ``Exif:SubsecTimeOriginal`` / ``Exif:SubsecTimeDigitized`` fraction and its
    own offset ``Exif:OffsetTimeOriginal`` / ``Exif:OffsetTimeDigitized``
    ("+HH:MM" or "-HH:MM"). With a valid offset, ``when`` is timezone-aware
    and has_offset is True; without one (older cameras), ``when`` is the naive
    camera-clock time and has_offset is False: ask the user for the UTC offset.
    The file's ``DateTime`` (last modification, rewritten by editors and by
    OIIO's TIFF writer) is never used. Malformed or blank values count as
    missing.
    """
    for stamp, subsec, offset in (
        ("Exif:DateTimeOriginal", "Exif:SubsecTimeOriginal", "Exif:OffsetTimeOriginal"),
        ("Exif:DateTimeDigitized", "Exif:SubsecTimeDigitized", "Exif:OffsetTimeDigitized"),
    ):
        when = _parse_datetime(_lookup(metadata, stamp))
        if when is None:
            continue
        digits = _clean_string(_lookup(metadata, subsec))
        if digits and digits.isdigit():
            micro = min(round(float("0." + digits) * 1e6), 999_999)
            when = when.replace(microsecond=micro)
        tz = _parse_offset(_lookup(metadata, offset))
        if tz is None:
            return CaptureTime(when, False)
        return CaptureTime(when.replace(tzinfo=tz), True)
    return None


def _dms_degrees(value) -> float | None:
    """Degrees from EXIF (degrees, minutes, seconds) or a single decimal value; None if invalid."""
    if value is None or isinstance(value, bool | str | bytes):
        return None
    try:
        parts = np.asarray(value, dtype=np.float64).ravel()
    except (TypeError, ValueError):
        return None
    if parts.size == 0 or parts.size > 3 or not np.all(np.isfinite(parts)) or np.any(parts < 0):
        return None
    if parts.size > 1 and np.any(parts[1:] > 60.0):
        return None
    return float(parts @ np.array([1.0, 1.0 / 60.0, 1.0 / 3600.0])[: parts.size])


def gps_position(metadata: dict) -> tuple[float, float] | None:
    """(latitude_deg, longitude_deg) of the photo from its GPS tags, or None.

    Degrees north and east (south and west negative), as core.capture.sun takes them.
    ``GPS:Latitude`` / ``GPS:Longitude`` are (degrees, minutes, seconds); the
    refs ``GPS:LatitudeRef`` ("N"/"S") and ``GPS:LongitudeRef`` ("E"/"W") are
    required (a value without its hemisphere is not guessed). None when a tag
    is missing or invalid, when the result is out of range, or when
    ``GPS:Status`` is "V" (the receiver marked the fix void).
    """
    status = _clean_string(_lookup(metadata, "GPS:Status"))
    if status is not None and status.upper() == "V":
        return None
    lat = _dms_degrees(_lookup(metadata, "GPS:Latitude"))
    lon = _dms_degrees(_lookup(metadata, "GPS:Longitude"))
    lat_ref = (_clean_string(_lookup(metadata, "GPS:LatitudeRef")) or "").upper()
    lon_ref = (_clean_string(_lookup(metadata, "GPS:LongitudeRef")) or "").upper()
    if lat is None or lon is None or lat_ref not in ("N", "S") or lon_ref not in ("E", "W"):
        return None
    lat = -lat if lat_ref == "S" else lat
    lon = -lon if lon_ref == "W" else lon
    if abs(lat) > 90.0 or abs(lon) > 180.0:
        return None
    return lat, lon
