"""How many Cycles samples the accurate KL path needs (issue 4: "the fewest the
comparison needs, chosen by measurement").

Scene: ``testkit/blender_scene.py`` (an icosphere scan, one 48 x 48 photo rendered
by Cycles with a Lambertian albedo 0.5 under a Sun). Candidates: Lambert 0.25,
the true Lambert 0.5, a held-out gold, Lambert 0.9. For each sample count the
KL of every candidate (Cycles path) and the time per render are measured; the
reference is 256 samples, and "enough" is the fewest samples that rank the
candidates as the reference does. Writes bench/results/cycles_kl.json.

Run: ``.venv/bin/python bench/cycles_kl_bench.py`` (part of ``make bench``).
"""

from __future__ import annotations

import argparse
import json
import pathlib
import tempfile
import time

import common
import numpy as np

SAMPLES = (1, 2, 4, 8, 16, 32, 64)
REFERENCE = 256


def main(argv=None) -> dict:
    parser = argparse.ArgumentParser(description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    args = parser.parse_args(argv)
    info = common.machine()
    import bpy

    import brdf_reconstruct
    from brdf_reconstruct.brdf_addon import cycles_select, gathering, photo_list
    from brdf_reconstruct.core.brdf import database, merl
    from brdf_reconstruct.core.method import pipeline, selection
    from testkit import blender_scene as BS

    def lambert(albedo):
        t = np.full((3, merl.N_CELLS), np.nan)
        t[:, merl.valid_cells()] = albedo / np.pi
        return t.reshape(3, *merl.SHAPE)

    tmp = pathlib.Path(tempfile.mkdtemp())
    built = BS.build(tmp)
    brdf_reconstruct.register()
    scene = built["scene"]
    scene.brdf.target = built["scan"]
    scene.brdf.output_dir = str(tmp / "out")  # absolute: the scene is never saved
    (p,), _ = photo_list.add_photos(scene, [str(built["photo"])])
    p.irradiance = (BS.lit_irradiance(),) * 3
    inputs = gathering.gather(scene)
    gold = common.heldout_spec("heldout_gold_medium")
    names = ["lambert_0.25", "lambert_0.5_truth", "heldout_gold_medium", "lambert_0.9"]
    tables = [lambert(0.25), lambert(BS.ALBEDO), database.make_table(gold), lambert(0.9)]
    fast = selection.select_by_kl(tables, pipeline.region_views(inputs, 0))
    rows = {}
    for n in (*SAMPLES, REFERENCE):
        t0 = time.perf_counter()
        kl = [float(cycles_select.score_candidate(scene, inputs, 0, t, render_samples=n).mean())
              for t in tables]
        rows[n] = {"kl": kl, "winner": int(np.argmin(kl)),
                   "seconds_per_render": (time.perf_counter() - t0) / len(tables)}
        print(n, np.round(kl, 4), f"{rows[n]['seconds_per_render']:.2f} s", flush=True)
    ref = np.array(rows[REFERENCE]["kl"])
    for n in SAMPLES:
        rows[n]["max_relative_kl_change_vs_reference"] = float(
            np.max(np.abs(np.array(rows[n]["kl"]) - ref) / ref))
    ranking = list(np.argsort(ref))
    enough = [n for n in SAMPLES if list(np.argsort(rows[n]["kl"])) == ranking]
    report = {
        "command": ".venv/bin/python bench/cycles_kl_bench.py",
        "machine": common.machine_end(info),
        "candidates": names, "fast_path_kl": fast.kl.tolist(), "fast_winner": fast.winner,
        "reference_samples": REFERENCE,
        "samples": {str(k): v for k, v in rows.items()},
        "fewest_samples_with_the_reference_ranking": enough[0] if enough else None,
    }
    common.write_json(common.RESULTS / "cycles_kl.json", report, arguments=args)
    brdf_reconstruct.unregister()
    print(json.dumps({k: report[k] for k in ("fast_path_kl",
                                              "fewest_samples_with_the_reference_ranking")},
                     indent=1))
    del bpy
    return report


if __name__ == "__main__":
    main()
