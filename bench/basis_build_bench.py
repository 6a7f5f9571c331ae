"""The shipped bases' first-use build: wall time, peak memory, how often the progress
line moves, and how fast Esc (``cancelled()``) stops it.

    .venv/bin/python bench/basis_build_bench.py [--cancel-after S] [--bases a,b]

For each basis (``measured``: the 80 materials of the shipped pack, the default;
``analytic``: the 150 of the built-in database), in a fresh child process (so each
peak memory is its own): a build into a throw-away cache folder (never the real
cache), timing every ``progress(fraction, message)`` call of
``core.brdf.basis.build_from``; then a second build that is cancelled after
``--cancel-after`` seconds, timing the delay from the request to
``core.progress.Cancelled``. Writes ``bench/results/basis_build.json``. About a
minute and a half on the 2-core machine.
"""

from __future__ import annotations

import argparse
import json
import pathlib
import subprocess
import sys
import tempfile
import threading
import time

import common
import numpy as np

from brdf_reconstruct.core import progress as core_progress
from brdf_reconstruct.core.brdf import basis

LOADERS = {"measured": basis.load_measured, "analytic": basis.load_default}


def _full_build(load, cache) -> dict:
    stamps, messages = [], []
    t0 = time.perf_counter()

    def progress(fraction, message):
        stamps.append(time.perf_counter() - t0)
        messages.append((round(fraction, 4), message))

    B = load(cache_dir=cache, progress=progress)
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


def _cancelled_build(load, cache, after: float) -> dict:
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
        load(cache_dir=cache, cancelled=cancelled)
        stopped = False
    except core_progress.Cancelled:
        stopped = True
    delay = time.perf_counter() - t_ask[0] if t_ask else float("nan")
    left = sorted(p.name for p in cache.iterdir()) if cache.exists() else []
    return {"cancel_after_s": after, "stopped": stopped, "stop_delay_s": delay,
            "files_left_in_cache": left}


def _child(name: str, after: float) -> dict:
    with tempfile.TemporaryDirectory() as tmp:
        full = _full_build(LOADERS[name], pathlib.Path(tmp) / "full")
        cancel = _cancelled_build(LOADERS[name], pathlib.Path(tmp) / "cancel", after)
    return {"build": full, "cancel": cancel}


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--cancel-after", type=float, default=5.0,
                        help="seconds into the second build to ask it to stop")
    parser.add_argument("--bases", default=",".join(LOADERS),
                        help=f"comma-separated, of {', '.join(LOADERS)}")
    parser.add_argument("--child", help=argparse.SUPPRESS)  # internal: one basis, JSON out
    args = parser.parse_args(argv)
    if args.child:
        print(json.dumps(_child(args.child, args.cancel_after)))
        return 0
    names = common.listed(args.bases, LOADERS, "--bases")
    if names is None:
        return 2
    info = common.machine("basis build, the shipped bases, each in its own process")
    doc = {"machine": info}
    for name in names:
        out = subprocess.run([sys.executable, __file__, "--child", name,
                              "--cancel-after", str(args.cancel_after)],
                             capture_output=True, text=True, check=True)
        doc[name] = json.loads(out.stdout.strip().splitlines()[-1])
        full, cancel = doc[name]["build"], doc[name]["cancel"]
        print(f"{name}: {full['n_columns']} columns, build {full['seconds']:.1f} s, peak "
              f"{full['peak_rss_gib']:.2f} GiB, {full['progress_calls']} progress calls, "
              f"longest gap {full['max_gap_s']:.2f} s; cancel after {args.cancel_after:g} s "
              f"stopped in {cancel['stop_delay_s']:.2f} s", flush=True)
    common.machine_end(info)
    path = common.write_json(common.RESULTS / "basis_build.json", doc, arguments=vars(args))
    print(f"-> {path}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
