"""Reference sun positions from Blender's Sun Position add-on, for tests/core/capture/test_sun.py.

Evaluates the add-on's own calculation (``sun_calc.get_sun_position`` in the
add-on 3.1.x that Blender 3.x-4.1 bundled; ``get_sun_coordinates`` in later
versions) for a fixed set of dates, times and places, and writes the results
to tests/data/sun_position_addon.json with the inputs and where they came from.

None of the add-on's code is copied here: the add-on is imported from where it
was unpacked and enabled through ``addon_utils`` (its calculation reads the
``use_refraction`` setting from the scene's add-on properties and looks up the
add-on's preferences, so it must be registered), then called directly.

The add-on is no longer bundled with Blender (since 4.2 it is an extension) and
PyPI keeps no ``bpy`` wheel older than 4.2, so the copy used comes from Debian's
``blender-data`` package (Blender 3.4.1). Any Blender-as-a-module (``bpy``)
provides the runtime it needs (bpy, mathutils). To regenerate, from the repo root:

    cd /tmp && apt-get download blender-data=3.4.1+dfsg-2
    .venv/bin/python bench/tools/sun_position_reference.py \\
        --deb /tmp/blender-data_3.4.1+dfsg-2_all.deb

or give ``--addons-dir`` (a folder that holds ``sun_position/``, e.g. a Blender
install's ``scripts/addons``) instead of ``--deb``.

Add-on conventions (read from its source, and recorded in the JSON):
- ``UTC_zone`` is hours east of Greenwich; ``use_daylight_savings`` adds one
  hour, so local civil time = UT + UTC_zone (+1 with DST). The calculation is
  called with ``utc_zone = -(UTC_zone + dst)``, as the add-on's own
  ``move_sun`` does. The date is the local calendar date; the add-on's Julian
  date is that date's 0h plus (local time - offset) / 24, so it rolls over
  correctly when the UT date differs.
- Azimuth in degrees clockwise from north (north 0, east 90), in [0, 360)
  with ``north_offset`` 0. Elevation in degrees above the horizon.
- Refraction: NOAA's formula when the scene property ``use_refraction`` is True
  (its default); both settings are evaluated here.
- Latitudes beyond +-89.93 are clamped by the add-on; the cases stay inside.
"""

from __future__ import annotations

import argparse
import datetime as dt
import hashlib
import json
import pathlib
import shlex
import subprocess
import sys
import tempfile

ROOT = pathlib.Path(__file__).resolve().parents[2]
DEFAULT_OUT = ROOT / "tests" / "data" / "sun_position_addon.json"
DEB_ADDONS = "usr/share/blender/scripts/addons"

# (name, local date, local time "HH:MM[:SS]", UTC_zone (h east), DST, latitude N, longitude E)
CASES = [
    ("paris_summer_afternoon_dst", "2024-06-21", "13:30", 1.0, True, 48.8566, 2.3522),
    ("paris_winter_midnight", "2024-12-21", "23:00", 1.0, False, 48.8566, 2.3522),
    ("greenwich_j2000_noon", "2000-01-01", "12:00", 0.0, False, 51.4769, 0.0),
    ("new_york_winter_morning", "2024-01-15", "09:00", -5.0, False, 40.7128, -74.0060),
    ("new_york_summer_evening_dst", "2024-07-04", "18:45", -5.0, True, 40.7128, -74.0060),
    ("los_angeles_near_sunset_utc_next_day", "2024-08-15", "19:40", -8.0, True, 34.0522, -118.2437),
    ("los_angeles_after_sunset", "2024-08-15", "20:05", -8.0, True, 34.0522, -118.2437),
    ("sydney_southern_summer_dst", "2024-12-21", "10:00", 10.0, True, -33.8688, 151.2093),
    ("sydney_southern_winter_noon", "2024-06-21", "12:00", 10.0, False, -33.8688, 151.2093),
    ("cape_town_summer_afternoon", "2023-01-10", "16:20", 2.0, False, -33.9249, 18.4241),
    ("buenos_aires_summer_morning", "2025-02-14", "08:15", -3.0, False, -34.6037, -58.3816),
    ("auckland_near_sunset_dst", "2024-01-01", "20:30", 12.0, True, -36.8485, 174.7633),
    ("tromso_midnight_sun_dst", "2024-06-21", "00:30", 1.0, True, 69.6492, 18.9553),
    ("tromso_polar_night_noon", "2024-12-21", "12:00", 1.0, False, 69.6492, 18.9553),
    ("longyearbyen_late_evening_dst", "2024-05-15", "22:00", 1.0, True, 78.2232, 15.6267),
    ("anchorage_winter_low_sun", "2024-12-21", "11:00", -9.0, False, 61.2181, -149.9003),
    ("reykjavik_equinox_near_sunrise", "2035-03-20", "07:35", 0.0, False, 64.1466, -21.9426),
    ("mcmurdo_southern_summer_dst", "2024-12-25", "03:00", 12.0, True, -77.8460, 166.6760),
    ("near_south_pole_solstice", "2024-12-21", "12:00", 0.0, False, -89.5, 0.0),
    ("quito_equinox_near_zenith", "2024-03-20", "12:10", -5.0, False, -0.1807, -78.4678),
    ("singapore_2001_near_sunrise", "2001-09-11", "07:15", 8.0, False, 1.3521, 103.8198),
    ("tokyo_2035_near_sunset", "2035-08-01", "18:40", 9.0, False, 35.6762, 139.6503),
    ("honolulu_2035_near_sunrise", "2035-11-30", "06:55", -10.0, False, 21.3069, -157.8583),
    ("mumbai_half_hour_zone", "2024-04-14", "13:00", 5.5, False, 19.0760, 72.8777),
    ("kathmandu_quarter_hour_zone_2001", "2001-02-01", "07:05", 5.75, False, 27.7172, 85.3240),
    ("apia_utc_plus_13_previous_utc_day", "2024-07-01", "09:00", 13.0, False, -13.8333, -171.75),
    ("fiji_near_antimeridian", "2024-10-05", "15:45:30", 12.0, False, -18.1248, 178.4419),
    ("leap_day_2000_denver", "2000-02-29", "10:20", -7.0, False, 39.7392, -104.9903),
    ("leap_day_2024_madrid_dst_like", "2024-02-29", "17:50", 1.0, False, 40.4168, -3.7038),
    ("spa_example_2003_golden", "2003-10-17", "12:30:30", -7.0, False, 39.742476, -105.1786),
    ("cairo_1985_morning", "1985-06-01", "08:00", 2.0, True, 30.0444, 31.2357),
    ("lima_2099_afternoon", "2099-09-23", "15:00", -5.0, False, -12.0464, -77.0428),
]


def _hours(hms: str) -> float:
    parts = [int(p) for p in hms.split(":")]
    parts += [0] * (3 - len(parts))
    return parts[0] + parts[1] / 60.0 + parts[2] / 3600.0


def _sha256(path: pathlib.Path) -> str:
    return hashlib.sha256(path.read_bytes()).hexdigest()


def _deb_field(deb: pathlib.Path, field: str) -> str:
    out = subprocess.run(["dpkg-deb", "-f", str(deb), field], capture_output=True, text=True)
    return out.stdout.strip()


def evaluate(addons_dir: pathlib.Path) -> tuple[list[dict], dict]:
    """Enable the add-on found in addons_dir and evaluate every case with it."""
    import bpy  # noqa: I001  (bpy first: it puts addon_utils on sys.path)
    import addon_utils

    # Blender's own add-on folder (unpacked from blender-data, or a Blender install's
    # scripts/addons): addon_utils.enable imports the add-on by name from sys.path, as
    # Blender does with its scripts folders. Not a project folder.
    sys.path.insert(0, str(addons_dir))
    mod = addon_utils.enable("sun_position", default_set=True, handle_error=None)
    if mod is None or not pathlib.Path(mod.__file__).is_relative_to(addons_dir):
        raise SystemExit(f"could not enable sun_position from {addons_dir} (got {mod!r})")
    from sun_position import sun_calc

    props = bpy.context.scene.sun_pos_properties
    probe = bpy.data.objects.new("sun_probe", None)  # the add-on places objects here
    results = []
    for name, date, hms, utc_zone, dst, lat, lon in CASES:
        y, m, d = (int(p) for p in date.split("-"))
        local_time = _hours(hms)
        offset = utc_zone + (1.0 if dst else 0.0)
        for refraction in (True, False):
            props.use_refraction = refraction
            # As the add-on's move_sun: zone = -UTC_zone, minus one hour with DST.
            args = (local_time, lat, lon, 0.0, -offset, m, d, y, 1.0)
            if hasattr(sun_calc, "get_sun_coordinates"):  # add-on >= 3.2
                _, theta, phi, azimuth, elevation = sun_calc.get_sun_coordinates(*args)
                direction = list(sun_calc.get_sun_vector(theta, phi))
            else:  # add-on 3.1.x: results left in the module's `sun` record
                sun_calc.get_sun_position(*args)
                azimuth, elevation = sun_calc.sun.azimuth, sun_calc.sun.elevation
                sun_calc.set_sun_position(probe, 1.0)
                direction = list(probe.location)
            local = dt.datetime(y, m, d, tzinfo=dt.timezone(dt.timedelta(hours=offset)))
            local += dt.timedelta(hours=local_time)
            results.append(
                {
                    "name": name,
                    "local_date": date,
                    "local_time": hms,
                    "local_time_hours": local_time,
                    "utc_zone_hours": utc_zone,
                    "use_daylight_savings": dst,
                    "utc_offset_hours": offset,
                    "iso_local": local.isoformat(),
                    "iso_utc": local.astimezone(dt.UTC).isoformat(),
                    "latitude_deg": lat,
                    "longitude_deg": lon,
                    "use_refraction": refraction,
                    "azimuth_deg": azimuth,
                    "elevation_deg": elevation,
                    "direction_enu": direction,
                }
            )
    info = {
        "addon_version": ".".join(str(v) for v in mod.bl_info["version"]),
        "addon_bl_info_blender": ".".join(str(v) for v in mod.bl_info["blender"]),
        "addon_calc_function": (
            "sun_calc.get_sun_coordinates"
            if hasattr(sun_calc, "get_sun_coordinates")
            else "sun_calc.get_sun_position"
        ),
        "sun_calc_sha256": _sha256(pathlib.Path(sun_calc.__file__)),
        "runtime_bpy_version": bpy.app.version_string,
    }
    return results, info


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    src = parser.add_mutually_exclusive_group(required=True)
    src.add_argument("--deb", type=pathlib.Path, help="Debian blender-data .deb to unpack")
    src.add_argument("--addons-dir", type=pathlib.Path, help="folder holding sun_position/")
    parser.add_argument("--out", type=pathlib.Path, default=DEFAULT_OUT)
    args = parser.parse_args(argv)

    source: dict = {}
    with tempfile.TemporaryDirectory() as tmp:
        if args.deb is not None:
            deb = args.deb.resolve()
            subprocess.run(["dpkg-deb", "-x", str(deb), tmp], check=True)
            addons_dir = pathlib.Path(tmp) / DEB_ADDONS
            source = {
                "kind": "Debian package",
                "package": _deb_field(deb, "Package"),
                "package_version": _deb_field(deb, "Version"),
                "file": deb.name,
                "file_sha256": _sha256(deb),
                "path_in_package": f"/{DEB_ADDONS}/sun_position/",
            }
        else:
            addons_dir = args.addons_dir.resolve()
            source = {"kind": "folder", "path": str(addons_dir / "sun_position")}
        cases, info = evaluate(addons_dir)

    command = " ".join(
        shlex.quote(a) for a in [".venv/bin/python", "bench/tools/sun_position_reference.py"]
    )
    command += " " + " ".join(shlex.quote(a) for a in (argv if argv is not None else sys.argv[1:]))
    doc = {
        "description": (
            "Sun positions from Blender's Sun Position add-on (its own calculation, "
            "called with north_offset 0) for tests/core/capture/test_sun.py."
        ),
        "generated_by": "bench/tools/sun_position_reference.py",
        "command": command.strip(),
        "generated_utc": dt.datetime.now(dt.UTC).replace(microsecond=0).isoformat(),
        "addon_source": source,
        **info,
        "conventions": {
            "time": (
                "local_time_hours on local_date, civil time = UT + utc_offset_hours, "
                "utc_offset_hours = utc_zone_hours + (1 if use_daylight_savings); the "
                "add-on was called with utc_zone = -utc_offset_hours as its move_sun does"
            ),
            "azimuth_deg": "degrees clockwise from geographic north (N 0, E 90, S 180, W 270)",
            "elevation_deg": (
                "degrees above the horizon; apparent (NOAA refraction) if use_refraction, "
                "else geometric"
            ),
            "direction_enu": (
                "the add-on's unit vector to the Sun in Blender world space with "
                "north_offset 0: +X east, +Y north, +Z up (stored as float32 object location)"
            ),
            "latitude_deg": "degrees north",
            "longitude_deg": "degrees east (west negative)",
        },
        "cases": cases,
    }
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.write_text(json.dumps(doc, indent=1) + "\n")
    print(f"wrote {len(cases)} cases to {args.out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
