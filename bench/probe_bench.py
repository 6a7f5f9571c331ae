"""The sphere probe in the field: angular error and uncertainty of the light found
from Cycles photos of a chrome and a glossy black (clear-coat) sphere (METHOD §7).

Scene: ``testkit/probe_scene.py``, the one the probe tests use
(``tests/blender/test_probe.py``): a sphere 7 degrees off the optical axis of a
35 mm camera, in front of a lit grey wall that takes its shadow; a 0.75 degree
Sun. Lights: 5 angles from the sphere-to-camera direction (10 to 75 degrees)
x 4 rolls. Each photo is analysed as rendered (HDR) and clipped at 1.0 (as a
camera would, the highlight's core flat), with the circle found by
`locate_sphere` ("auto") and with the true circle ("true"), which separates the
circle's share of the error from the highlight's. Configurations: 320 x 240 at
32 samples (the tests' set-up, sphere radius 89 px), 256 x 192 at 16 samples
(71 px) and, for the 68-ish degree lights only, 640 x 480 at 32 samples (178 px).

Writes bench/results/light_probe.json: every case, and per configuration the
median and largest error and how often the error is below the reported
uncertainty (and below twice it); and bench/results/light_probe.png: the error
against the light's angle from the view, per sphere, HDR and clipped, with the
reported uncertainty, for the circle `locate_sphere` found. About 2 minutes on
the 2-core machine.

Run: ``.venv/bin/python bench/probe_bench.py`` (``--quick``: 320 x 240 only).
"""

from __future__ import annotations

import argparse
import math
import pathlib
import tempfile
import time

import common
import numpy as np

ANGLES = (10.0, 30.0, 50.0, 65.0, 75.0)
ROLLS = (30.0, 120.0, 210.0, 300.0)
CONFIGS = (  # (size, samples, angles)
    ((320, 240), 32, ANGLES),
    ((256, 192), 16, ANGLES),
    ((640, 480), 32, (65.0,)),
)


def _angle_deg(a, b):
    a, b = np.asarray(a, float), np.asarray(b, float)
    return math.degrees(math.acos(np.clip(a @ b / np.linalg.norm(a) / np.linalg.norm(b), -1, 1)))


def measure(photo) -> dict:
    """Errors and uncertainties (degrees) of one photo, HDR and clipped, auto and true circle."""
    from brdf_reconstruct.core.capture import light_probe as lp

    cam, rot = photo["camera"], photo["rotation"]
    t0 = time.perf_counter()
    (cx, cy), r = lp.locate_sphere(photo["image"], camera=cam)
    row = {"locate_s": time.perf_counter() - t0}
    (tx, ty), tr = photo["circle"]
    row.update(radius_px=tr, centre_error_px=math.hypot(cx - tx, cy - ty), radius_error_px=r - tr)
    for tone, image in (("hdr", photo["image"]), ("clipped", np.minimum(photo["image"], 1.0))):
        for which, circle in (("auto", ((cx, cy), r)), ("true", photo["circle"])):
            res = lp.light_from_sphere(image, *circle, cam, rot)
            row[f"{tone}_{which}"] = {
                "error_deg": _angle_deg(res.direction_world, photo["light"]),
                "uncertainty_deg": math.degrees(res.uncertainty_rad),
            }
    return row


def summarise(rows) -> dict:
    out = {}
    for key in ("hdr_auto", "hdr_true", "clipped_auto", "clipped_true"):
        err = np.array([r[key]["error_deg"] for r in rows])
        unc = np.array([r[key]["uncertainty_deg"] for r in rows])
        out[key] = {
            "median_error_deg": float(np.median(err)),
            "max_error_deg": float(err.max()),
            "median_uncertainty_deg": float(np.median(unc)),
            "fraction_error_below_uncertainty": float(np.mean(err < unc)),
            "fraction_error_below_2x_uncertainty": float(np.mean(err < 2 * unc)),
            "max_error_over_uncertainty": float(np.max(err / unc)),
        }
    out["max_centre_error_px"] = float(max(r["centre_error_px"] for r in rows))
    out["mean_radius_error_px"] = float(np.mean([r["radius_error_px"] for r in rows]))
    return out


def main(argv=None) -> dict:
    parser = argparse.ArgumentParser(description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--quick", action="store_true", help="320 x 240 only")
    args = parser.parse_args(argv)
    quick = args.quick
    info = common.machine()
    from testkit import probe_scene as scene

    tmp = pathlib.Path(tempfile.mkdtemp())
    cases, summary = [], {}
    t_start = time.perf_counter()
    for size, samples, angles in CONFIGS[:1] if quick else CONFIGS:
        for kind in scene.KINDS:
            rows = []
            for angle in angles:
                for roll in ROLLS:
                    t0 = time.perf_counter()
                    photo = scene.render_probe(tmp / "probe.exr", kind,
                                               scene.light_from_view(angle, roll),
                                               size=size, samples=samples)
                    row = {"kind": kind, "size": list(size), "samples": samples,
                           "angle_deg": angle, "roll_deg": roll,
                           "render_s": time.perf_counter() - t0, **measure(photo)}
                    rows.append(row)
                    print(f"{kind:6s} {size[0]}x{size[1]} {samples:2d} spp {angle:4.0f} "
                          f"{roll:4.0f}: auto hdr {row['hdr_auto']['error_deg']:.2f} "
                          f"(unc {row['hdr_auto']['uncertainty_deg']:.2f}), clipped "
                          f"{row['clipped_auto']['error_deg']:.2f} deg", flush=True)
            cases += rows
            summary[f"{kind} {size[0]}x{size[1]} {samples}spp"] = summarise(rows)
    result = {
        "what": "light direction from a Cycles photo of a probe sphere: error vs the Sun's "
                "true direction, and light_probe's uncertainty (degrees)",
        "scene": "testkit/probe_scene.py (the probe tests' scene): sphere 7 deg off axis, "
                 "grey wall with its shadow, 0.75 deg Sun, chrome (Glossy 0.03) or black "
                 "clear coat (0.03)",
        "angles_deg": list(ANGLES), "rolls_deg": list(ROLLS),
        "summary": summary,
        "cases": cases,
        "total_s": time.perf_counter() - t_start,
        "machine": common.machine_end(info),
    }
    out = common.write_json(common.RESULTS / "light_probe.json", result, arguments=args)
    plot(result, out.with_suffix(".png"))
    for name, s in summary.items():
        print(f"{name}: " + ", ".join(
            f"{k} median {v['median_error_deg']:.2f} max {v['max_error_deg']:.2f} "
            f"(< unc {v['fraction_error_below_uncertainty']:.0%}, "
            f"< 2 unc {v['fraction_error_below_2x_uncertainty']:.0%})"
            for k, v in s.items() if isinstance(v, dict)))
    print(f"wrote {out} and {out.with_suffix('.png').name} in {result['total_s']:.0f} s")
    return result


def plot(result: dict, path: pathlib.Path) -> None:
    """Error (degrees) against the light's angle from the view: a panel per sphere (rows)
    and tone (columns: HDR, clipped), a colour per configuration; dots are photos (one
    per roll), the dashed line is the median reported uncertainty (1 sigma) per angle.
    The circle is the one `locate_sphere` found ("auto"); the JSON also has the true one."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    cases = result["cases"]
    kinds = list(dict.fromkeys(c["kind"] for c in cases))
    configs = list(dict.fromkeys((tuple(c["size"]), c["samples"]) for c in cases))
    colours = ("tab:blue", "tab:orange", "tab:green", "tab:red")
    fig, axes = plt.subplots(len(kinds), 2, figsize=(12, 4.2 * len(kinds)), sharex=True,
                             sharey=True, squeeze=False)
    for row, kind in enumerate(kinds):
        for col, tone in enumerate(("hdr", "clipped")):
            ax = axes[row, col]
            key = f"{tone}_auto"
            for i, (size, samples) in enumerate(configs):
                sel = [c for c in cases if c["kind"] == kind
                       and (tuple(c["size"]), c["samples"]) == (size, samples)]
                if not sel:
                    continue
                shift = 1.6 * (i - (len(configs) - 1) / 2)  # degrees, so the dots do not overlap
                err = np.array([c[key]["error_deg"] for c in sel])
                angles = sorted({c["angle_deg"] for c in sel})
                unc = [np.median([c[key]["uncertainty_deg"] for c in sel
                                  if c["angle_deg"] == a]) for a in angles]
                radius = np.median([c["radius_px"] for c in sel])
                colour = colours[i % len(colours)]
                ax.plot(np.array([c["angle_deg"] for c in sel]) + shift, err, "o", ms=5,
                        color=colour, alpha=0.8,
                        label=f"{size[0]}x{size[1]} {samples} spp (r {radius:.0f} px): "
                              f"median {np.median(err):.2f}, max {err.max():.2f} deg")
                ax.plot(np.array(angles) + shift, unc, "--", marker="_", ms=14, mew=2,
                        color=colour, lw=1.2)
            ax.plot([], [], "k--", lw=1.2, label="dashes: median reported uncertainty (1 sigma)")
            ax.set_title(f"{kind} sphere, {'HDR' if tone == 'hdr' else 'clipped at 1.0'}",
                         fontsize=10)
            ax.grid(alpha=0.3)
            ax.legend(fontsize=8, loc="upper left")
            if col == 0:
                ax.set_ylabel("angular error of the light (degrees)")
            if row == len(kinds) - 1:
                ax.set_xlabel("light's angle from the view (degrees), 4 rolls each")
    axes[0, 0].set_ylim(bottom=0.0)
    axes[0, 0].set_ylim(top=axes[0, 0].get_ylim()[1] * 1.35)  # room for the legend
    axes[0, 0].set_xticks(result["angles_deg"])
    fig.suptitle("Light from a Cycles photo of a probe sphere, circle found by locate_sphere "
                 "(bench/probe_bench.py)", fontsize=11)
    fig.tight_layout()
    fig.savefig(path, dpi=100)
    plt.close(fig)


if __name__ == "__main__":
    main()
