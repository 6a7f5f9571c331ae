"""The built-in basis' first-use build: wall time, peak memory, how often its progress
line moves, and how fast Esc (``cancelled()``) stops it.

    .venv/bin/python bench/basis_build_bench.py [--cancel-after S]

Builds the built-in basis into a throw-away cache folder (never the real cache),
timing every ``progress(fraction, message)`` call of ``core.brdf.basis.build``; then
a second build that is cancelled after ``--cancel-after`` seconds, timing the delay
from the request to ``core.progress.Cancelled``. Writes
``bench/results/basis_build.json``. About 2 to 3 minutes on the 2-core machine.
"""

from __future__ import annotations

import argparse
import pathlib
import sys
import tempfile
import threading
import time

import common
import numpy as np

from brdf_reconstruct.core import progress as core_progress
from brdf_reconstruct.core.brdf import basis


def _full_build(cache) -> dict:
    stamps, messages = [], []
    t0 = time.perf_counter()

    def progress(fraction, message):
        stamps.append(time.perf_counter() - t0)
        messages.append((round(fraction, 4), message))

    B = basis.load_default(cache_dir=cache, progress=progress)
    total = time.perf_counter() - t0
    gaps = np.diff([0.0, *stamps, total])
    fractions = [f for f, _ in messages]
    after = [m for _, m in messages] + ["(the build returns)"]
    longest = [{"gap_s": float(gaps[i]), "before": after[i]} for i in np.argsort(gaps)[::-1][:5]]
    return {"seconds": total, "peak_rss_gib": common.proc_status_bytes("VmHWM") / common.GIB,
            "progress_calls": len(stamps), "max_gap_s": float(gaps.max()),
            "p95_gap_s": float(np.percentile(gaps, 95)), "longest_gaps": longest,
            "fractions_rise": bool(np.all(np.diff(fractions) >= 0)),
            "last_fraction": fractions[-1], "first_message": messages[0][1],
            "last_message": messages[-1][1], "n_columns": B.info["n_columns"],
            "n_cells": B.info["n_cells"]}


def _cancelled_build(cache, after: float) -> dict:
    asked = threading.Event()
    t_ask = []

    def cancelled():
        return asked.is_set()

    def ask():
        time.sleep(after)
        t_ask.append(time.perf_counter())
        asked.set()

    threading.Thread(target=ask, daemon=True).start()
    try:
        basis.load_default(cache_dir=cache, cancelled=cancelled)
        stopped = False
    except core_progress.Cancelled:
        stopped = True
    delay = time.perf_counter() - t_ask[0] if t_ask else float("nan")
    left = sorted(p.name for p in cache.iterdir()) if cache.exists() else []
    return {"cancel_after_s": after, "stopped": stopped, "stop_delay_s": delay,
            "files_left_in_cache": left}


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--cancel-after", type=float, default=10.0,
                        help="seconds into the second build to ask it to stop")
    args = parser.parse_args(argv)
    info = common.machine("basis build, built-in analytic database")
    with tempfile.TemporaryDirectory() as tmp:
        full = _full_build(pathlib.Path(tmp) / "full")
        cancel = _cancelled_build(pathlib.Path(tmp) / "cancel", args.cancel_after)
    doc = {"machine": common.machine_end(info), "build": full, "cancel": cancel}
    path = common.write_json(common.RESULTS / "basis_build.json", doc, arguments=vars(args))
    print(f"build {full['seconds']:.0f} s, peak {full['peak_rss_gib']:.2f} GiB, "
          f"{full['progress_calls']} progress calls, longest gap {full['max_gap_s']:.2f} s; "
          f"cancel after {args.cancel_after:g} s stopped in {cancel['stop_delay_s']:.2f} s "
          f"-> {path}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
