"""``make bench``: every benchmark in turn; results land in ``bench/results/``.

About 4 hours on the 2-core machine, and the integrable normal correction
(``normal_correction_bench.py --field height``) ~26 min more: reliable_bench
(~45 min), tradeoff (~1 h), heldout with the Mitsuba peer (~20 min), scaling, extremes, SfM, core,
the basis build (~3 min), the bases against measured materials (~25 min), the
Cycles KL samples, the sphere probe (~2 min), the bad-input sweep (~4 to 8 min)
and camera-style inputs (~13 min). ``--quick`` runs the reduced version of each that has one.
``bench/README.md`` is the index: which question each answers, its result file
and headline number.
"""

from __future__ import annotations

import argparse
import subprocess
import sys
from pathlib import Path

HERE = Path(__file__).resolve().parent
# each in its own process: they set their own thread pinning and Blender scenes; an entry
# is a script and the arguments of its own it always gets
SCRIPTS = ("core_bench.py", "basis_build_bench.py", "measured_bench.py", "fig4_bench.py",
           "sampler_bench.py", "photo_bench.py", "normal_correction_bench.py",
           "normal_correction_bench.py --field height",
           "trial_combination_bench.py", "refit_bench.py", "irradiance_bench.py",
           "optics_bench.py", "footprint_bench.py", "photo_check_bench.py",
           "photo_count_bench.py", "refit_draw_bench.py", "clipping_bench.py",
           "texture_bench.py", "texture_figure.py", "principled_bench.py",
           "reliable_bench.py",
           "cycles_kl_bench.py", "kl_agreement_bench.py", "tradeoff.py", "extremes_bench.py",
           "bad_inputs.py",
           "scaling_bench.py", "sfm.py", "heldout_bench.py", "probe_bench.py",
           "camera_inputs_bench.py")
# no reduced version
NO_QUICK = ("cycles_kl_bench.py", "sfm.py", "camera_inputs_bench.py", "basis_build_bench.py",
            "fig4_bench.py", "texture_figure.py")
# arguments a script always gets (sfm.py prints only unless told where to write)
ALWAYS = {"sfm.py": ["--out", str(HERE / "results" / "sfm.json")]}
# arguments of the full run only (the ones its committed result file was made with)
FULL = {"kl_agreement_bench.py": ["--seeds", "3", "--cycles-samples", "4,16"]}


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--quick", action="store_true",
                        help="the reduced version of each benchmark that has one")
    quick = parser.parse_args(argv).quick
    failed = []
    for script in SCRIPTS:
        if quick:
            extra = [] if script in NO_QUICK else ["--quick"]
        else:
            extra = FULL.get(script, [])
        name, *own = script.split()
        args = own + ALWAYS.get(script, []) + extra
        print(f"== {name} {' '.join(args)}", flush=True)
        if subprocess.run([sys.executable, str(HERE / name), *args]).returncode != 0:
            failed.append(script)
    if failed:
        print(f"error: failed: {', '.join(failed)}", file=sys.stderr)
        return 1
    return 0


if __name__ == "__main__":
    sys.exit(main())
