"""The Principled BSDF version of the bake against the node group (issue 16): each
one's error against the table, measured in Cycles.

    .venv/bin/python bench/principled_bench.py [--quick]

For the 12 analytic held-out materials and one measured material per class
(``common.pipeline_materials``), the true table is fitted (``core.bake.fitting.fit``,
the bake every run makes), and both materials are built from that fit: the "BRDF
Reconstruction" node group (``brdf_addon.material.build_material``) and its
Principled BSDF version (``build_principled_material``, ``core.bake.principled``).
Each is rendered by Cycles on a sphere under the two bake lights and compared with
numpy shading of the table (``material.bake_error``: relative RMSE, the larger of
the two lights). So the numbers are what a run's report gives for a perfect
reconstruction: the cost of each material kind alone.

Writes ``bench/results/principled.json`` and ``principled.png`` (``--quick``:
``principled_quick.*``, 4 materials). About 2 minutes on the 2-core machine.
"""

from __future__ import annotations

import argparse
import json
import sys
import time

import common
import numpy as np


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="4 materials")
    args = parser.parse_args(argv)
    if common.measured_pack_or_error() is None:
        return 1
    import bpy  # noqa: F401 - pip bpy

    from brdf_reconstruct.brdf_addon import material, outputs
    from brdf_reconstruct.core.bake import fitting

    info = common.machine()
    names = common.pipeline_materials()
    if args.quick:
        names = names[:2] + names[-2:]
    rows = []
    t0 = time.perf_counter()
    for name in names:
        table = common.heldout_table(name)
        fit = fitting.fit(table)
        row = {"material": name, "measured": common.is_measured(name)}
        for kind, build in (("node_group", material.build_material),
                            ("principled", material.build_principled_material)):
            mat = build(f"{kind} {name}", fit, {})
            err = material.bake_error(mat, table, outputs.BAKE_LIGHTS)
            row[kind] = float(err["max"])
            if kind == "principled":
                row["principled_params"] = json.loads(mat["brdf_principled"])
            bpy.data.materials.remove(mat)
        rows.append(row)
        print(f"{name}: node group {row['node_group']:.3f}, Principled {row['principled']:.3f}",
              flush=True)
    summary = {}
    for group, sel in (("all", rows), ("analytic", [r for r in rows if not r["measured"]]),
                       ("measured", [r for r in rows if r["measured"]])):
        if sel:
            summary[group] = {
                "materials": len(sel),
                "node_group_median": float(np.median([r["node_group"] for r in sel])),
                "principled_median": float(np.median([r["principled"] for r in sel])),
                "principled_within_1_5x_node_group": int(sum(
                    r["principled"] <= 1.5 * r["node_group"] for r in sel)),
            }
    stem = "principled_quick" if args.quick else "principled"
    doc = {"machine": common.machine_end(info), "minutes": (time.perf_counter() - t0) / 60,
           "lights": outputs.BAKE_LIGHTS.tolist(), "summary": summary, "rows": rows}
    common.write_json(common.RESULTS / f"{stem}.json", doc, arguments=vars(args))
    plot(rows, common.RESULTS / f"{stem}.png")
    print(summary)
    return 0


def plot(rows, path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(11, 4.5))
    x = np.arange(len(rows))
    ax.bar(x - 0.2, [r["node_group"] for r in rows], 0.4, label="node group")
    ax.bar(x + 0.2, [r["principled"] for r in rows], 0.4, label="Principled BSDF")
    ax.set_yscale("log")
    ax.set_ylabel("bake error against the table (Cycles, max of 2 lights)")
    ax.set_xticks(x)
    ax.set_xticklabels([r["material"].replace("heldout_", "") for r in rows], rotation=70,
                       fontsize=7)
    ax.legend()
    common.save_figure(fig, path)


if __name__ == "__main__":
    sys.exit(main())
