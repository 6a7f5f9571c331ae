"""Sun position from date, time and place (METHOD §7).

The NOAA solar-position algorithm, as in NOAA's Solar Calculator spreadsheet,
which follows Meeus, *Astronomical Algorithms* (1991), ch. 24-28 in low
precision: the Sun's geometric mean longitude and anomaly, the equation of
centre, a one-term nutation/aberration correction to the apparent longitude,
the corrected obliquity, then declination and the equation of time. The local
hour angle comes from true solar time. Accuracy is about 0.01 degree for dates
between 1800 and 2100 (NOAA's own claim; checked here against NREL SPA).

Time is taken as UT (the difference from Terrestrial Time, about a minute
today, moves the Sun by under 0.001 degree). The position is geocentric; the
topocentric parallax is at most 0.0025 degree and is ignored.

Frames and units: angles are radians. Elevation is above the horizon; azimuth
is measured clockwise from geographic north (north 0, east pi/2, south pi).
Latitude is degrees north, longitude degrees east (west is negative). The
direction frame is local east-north-up: +X east, +Y north, +Z up.
"""

from __future__ import annotations

import datetime as _dt
from collections.abc import Iterable

import numpy as np

_J2000 = _dt.datetime(2000, 1, 1, 12, tzinfo=_dt.UTC)  # JD 2451545.0


def julian_day(when) -> np.ndarray | float:
    """Julian day number (UT) of a timezone-aware datetime or sequence of them.

    when: datetime with tzinfo, or an iterable of such datetimes.
    Returns a float, or (N,) float64 for a sequence. Raises ValueError for a
    naive datetime, since its instant is ambiguous.
    """
    if isinstance(when, _dt.datetime):
        return 2451545.0 + _seconds_since_j2000(when, "when") / 86400.0
    if isinstance(when, str | bytes) or not isinstance(when, Iterable):
        raise ValueError(
            "when must be a timezone-aware datetime or a sequence of them, "
            f"got {type(when).__name__}"
        )
    seconds = [_seconds_since_j2000(w, f"when[{i}]") for i, w in enumerate(when)]
    return 2451545.0 + np.asarray(seconds, dtype=np.float64) / 86400.0


def _seconds_since_j2000(when, name: str) -> float:
    if not isinstance(when, _dt.datetime):
        raise ValueError(f"{name} must be a datetime, got {type(when).__name__}")
    if when.tzinfo is None or when.utcoffset() is None:
        raise ValueError(
            f"{name} is a naive datetime ({when.isoformat()}); give it a timezone, "
            "e.g. datetime(..., tzinfo=datetime.timezone.utc)"
        )
    return (when - _J2000).total_seconds()


def _ephemeris(jd):
    """Declination (rad), equation of time (min) and UT minutes of day for JD (UT).

    NOAA spreadsheet columns G..V; angles in degrees until the end.
    """
    jc = (jd - 2451545.0) / 36525.0  # Julian centuries since J2000
    mean_long = np.mod(280.46646 + jc * (36000.76983 + jc * 0.0003032), 360.0)
    mean_anom = 357.52911 + jc * (35999.05029 - 0.0001537 * jc)
    ecc = 0.016708634 - jc * (0.000042037 + 0.0000001267 * jc)
    m = np.radians(mean_anom)
    centre = (
        np.sin(m) * (1.914602 - jc * (0.004817 + 0.000014 * jc))
        + np.sin(2 * m) * (0.019993 - 0.000101 * jc)
        + np.sin(3 * m) * 0.000289
    )
    true_long = mean_long + centre
    omega = np.radians(125.04 - 1934.136 * jc)  # longitude of the Moon's node
    apparent_long = true_long - 0.00569 - 0.00478 * np.sin(omega)
    obliq_arcsec = 21.448 - jc * (46.815 + jc * (0.00059 - jc * 0.001813))
    mean_obliq = 23.0 + (26.0 + obliq_arcsec / 60.0) / 60.0
    obliq = np.radians(mean_obliq + 0.00256 * np.cos(omega))
    declination = np.arcsin(np.sin(obliq) * np.sin(np.radians(apparent_long)))
    # Equation of time, Meeus eq. (28.3) (Smart's series), in minutes of time.
    y = np.tan(obliq / 2) ** 2
    l0 = np.radians(mean_long)
    eot = 4.0 * np.degrees(
        y * np.sin(2 * l0)
        - 2 * ecc * np.sin(m)
        + 4 * ecc * y * np.sin(m) * np.cos(2 * l0)
        - 0.5 * y * y * np.sin(4 * l0)
        - 1.25 * ecc * ecc * np.sin(2 * m)
    )
    # JD starts at noon, so the UT day fraction is offset by half a day.
    minutes_of_day = np.mod(jd - 0.5, 1.0) * 1440.0
    return declination, eot, minutes_of_day


def solar_declination(when) -> np.ndarray | float:
    """Apparent solar declination in radians (scalar, or (N,) for a sequence of times)."""
    dec, _, _ = _ephemeris(julian_day(when))
    return _scalar_if_0d(dec)


def equation_of_time(when) -> np.ndarray | float:
    """Equation of time in minutes (apparent minus mean solar time; scalar or (N,))."""
    _, eot, _ = _ephemeris(julian_day(when))
    return _scalar_if_0d(eot)


def atmospheric_refraction(elevation_rad) -> np.ndarray | float:
    """NOAA's refraction correction (radians) to add to a geometric elevation (radians).

    The piecewise formula of NOAA's Solar Calculator, for a standard
    atmosphere (about 1010 hPa, 10 degC): zero above 85 degrees; the series
    58.1"/tan e - 0.07"/tan^3 e + 0.000086"/tan^5 e above 5 degrees; a
    polynomial in e near the horizon (about 0.57 degree at e = 0); and
    -20.772"/tan e below -0.575 degree. Real refraction near the horizon
    varies with the weather by a tenth of a degree or more.
    """
    e = np.degrees(np.asarray(elevation_rad, dtype=np.float64))
    with np.errstate(divide="ignore", invalid="ignore"):
        t = np.tan(np.radians(e))
        high = 58.1 / t - 0.07 / t**3 + 0.000086 / t**5
        low = -20.772 / t
    near = 1735.0 + e * (-518.2 + e * (103.4 + e * (-12.79 + e * 0.711)))
    arcsec = np.where(e > 85.0, 0.0, np.where(e > 5.0, high, np.where(e > -0.575, near, low)))
    return _scalar_if_0d(np.radians(arcsec / 3600.0))


def solar_position(when, latitude_deg, longitude_deg, *, refraction: bool = True):
    """Solar elevation and azimuth (NOAA algorithm).

    when: timezone-aware datetime, or a sequence of N of them (naive raises ValueError).
    latitude_deg: degrees north in [-90, 90]; longitude_deg: degrees east in
    [-180, 180]. Either may be an array broadcasting against the times.
    refraction: add NOAA's atmospheric refraction (see `atmospheric_refraction`)
    to the elevation, i.e. return the apparent Sun; False gives the geometric
    (airless) elevation.

    Returns (elevation_rad, azimuth_rad): floats, or arrays of the broadcast
    shape. Azimuth is in [0, 2 pi), clockwise from north.
    """
    lat = _check_range(latitude_deg, "latitude_deg", -90.0, 90.0)
    lon = _check_range(longitude_deg, "longitude_deg", -180.0, 180.0)
    dec, eot, minutes = _ephemeris(julian_day(when))
    true_solar_minutes = np.mod(minutes + eot + 4.0 * lon, 1440.0)
    hour_angle = np.radians(true_solar_minutes / 4.0 - 180.0)
    phi = np.radians(lat)
    # The Sun in local east-north-up coordinates (equatorial -> horizontal).
    east = -np.cos(dec) * np.sin(hour_angle)
    north = np.sin(dec) * np.cos(phi) - np.cos(dec) * np.sin(phi) * np.cos(hour_angle)
    up = np.sin(dec) * np.sin(phi) + np.cos(dec) * np.cos(phi) * np.cos(hour_angle)
    elevation = np.arctan2(up, np.hypot(east, north))
    azimuth = np.mod(np.arctan2(east, north), 2 * np.pi)
    if refraction:
        elevation = elevation + atmospheric_refraction(elevation)
    return _scalar_if_0d(elevation), _scalar_if_0d(azimuth)


def sun_direction(when, latitude_deg, longitude_deg, *, refraction: bool = True) -> np.ndarray:
    """Unit vector towards the Sun in the local frame +X east, +Y north, +Z up.

    Arguments as for `solar_position`. Returns (3,) float64 for one time and
    place, else (..., 3): (cos(el) sin(az), cos(el) cos(az), sin(el)).
    The Sun may be below the horizon (z < 0); see `check_above_horizon`.
    """
    el, az = solar_position(when, latitude_deg, longitude_deg, refraction=refraction)
    el, az = np.asarray(el), np.asarray(az)
    return np.stack([np.cos(el) * np.sin(az), np.cos(el) * np.cos(az), np.sin(el)], axis=-1)


def check_above_horizon(direction, when=None, latitude_deg=None, longitude_deg=None) -> np.ndarray:
    """Return `direction` ((3,) or (..., 3), +Z up) if the Sun is above the horizon.

    Raises ValueError "the sun is below the horizon at <time, place>" if any
    direction has z <= 0. The optional time and place only make the message
    clearer for the user.
    """
    d = np.asarray(direction, dtype=np.float64)
    if d.shape[-1:] != (3,):
        raise ValueError(f"direction must have shape (3,) or (..., 3), got {d.shape}")
    if np.all(d[..., 2] > 0.0):
        return d
    where = []
    if isinstance(when, _dt.datetime):
        where.append(when.isoformat(sep=" "))
    if latitude_deg is not None and longitude_deg is not None and np.ndim(latitude_deg) == 0:
        where.append(f"latitude {float(latitude_deg):.4f}, longitude {float(longitude_deg):.4f}")
    at = ", ".join(where) if where else "the requested time and place"
    raise ValueError(f"the sun is below the horizon at {at}")


def _check_range(value, name: str, lo: float, hi: float) -> np.ndarray:
    try:
        a = np.asarray(value, dtype=np.float64)
    except (TypeError, ValueError):
        raise ValueError(f"{name} must be a number, got {value!r}") from None
    if not np.all(np.isfinite(a)):
        raise ValueError(f"{name} must be finite, got {value!r}")
    if np.any(a < lo) or np.any(a > hi):
        raise ValueError(f"{name} must be in [{lo:g}, {hi:g}] degrees, got {value!r}")
    return a


def _scalar_if_0d(a):
    a = np.asarray(a)
    return float(a) if a.ndim == 0 else a
