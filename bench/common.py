"""What every benchmark shares: the machine description, the results writer, and the
set-up steps more than one bench repeats. Bench-only; what tests share too lives in
``testkit/``.

- :func:`machine`: one description of the machine a run is on (CPU count,
  platform, Python and package versions, memory, load average, thread pinning),
  recorded as ``"machine"`` in every result file; :func:`machine_end` adds the
  load average when the run ends.
- :func:`write_json`: the one results writer. It records how the file was made
  (:func:`invocation`: the interpreter, ``sys.argv``, the parsed arguments, the
  working folder, the ``BRDF_*`` environment, the git commit) and writes through
  a temporary file beside the target, moved into place with ``os.replace``, so an
  interrupted run never leaves half a JSON file in ``bench/results/``.
- :func:`ensure_capture`, :func:`run_batch`, :func:`heldout_spec`: the demo's
  capture (generated once into the cache), the batch entry in a fresh
  subprocess, a held-out material by name.
- :func:`proc_status_bytes`, :func:`meminfo_bytes`: ``/proc`` memory readings.

Scripts import it as ``import common``: a script run as ``python bench/x.py`` has
``bench/`` first on ``sys.path``.
"""

from __future__ import annotations

import argparse
import functools
import json
import os
import pathlib
import platform
import shlex
import subprocess
import sys
import time
from importlib import metadata

HERE = pathlib.Path(__file__).resolve().parent
ROOT = HERE.parent
RESULTS = HERE / "results"
GIB = 2**30

# The demo's capture (bench/demo.py's defaults): 6 cameras on the COLMAP ring, 3 lit
# photos of 240 x 180, scan seed 0.
DEMO_CAPTURE = {"views": 6, "lit": 3, "resolution": (240, 180), "seed": 0}

# Versions recorded in the machine description: key -> distribution name. Looked up in
# the installed metadata (nothing is imported); a package not installed is left out.
PACKAGES = {"numpy": "numpy", "scipy": "scipy", "openimageio": "OpenImageIO",
            "pycolmap": "pycolmap", "bpy": "bpy", "mitsuba": "mitsuba",
            "matplotlib": "matplotlib"}
THREAD_VARIABLES = ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS")
# Environment that changes what a run reads or writes (the basis and capture cache, the
# ground-truth meshes): recorded with the command (the thread pinning is in machine()).
ENVIRONMENT = ("BRDF_RECONSTRUCT_CACHE", "BRDF_SHARED_DATA")


# --------------------------------------------------------------------------- machine


def _proc_kib_entry(path: str, key: str) -> int:
    """The ``key: <n> kB`` entry of a /proc file in bytes; 0 if absent or unreadable."""
    try:
        with open(path) as f:
            for line in f:
                if line.startswith(key + ":"):
                    return int(line.split()[1]) * 1024
    except OSError:
        pass
    return 0


def meminfo_bytes(key: str) -> int:
    """A /proc/meminfo entry (``MemTotal``, ``MemAvailable``) in bytes; 0 if absent."""
    return _proc_kib_entry("/proc/meminfo", key)


def proc_status_bytes(key: str, pid: int | str = "self") -> int:
    """An entry of /proc/<pid>/status in bytes: ``VmRSS`` (resident memory now) or
    ``VmHWM`` (its peak since the process's last exec); 0 if unreadable."""
    return _proc_kib_entry(f"/proc/{pid}/status", key)


def package_versions() -> dict:
    """Installed versions of :data:`PACKAGES` (key -> version string)."""
    out = {}
    for key, name in PACKAGES.items():
        try:
            out[key] = metadata.version(name)
        except metadata.PackageNotFoundError:
            continue
    return out


def machine(note: str | None = None) -> dict:
    """The machine this run is on, at its start.

    Keys: ``cpu_count``; ``platform``; ``python``; the versions of the installed
    :data:`PACKAGES` (``numpy``, ``scipy``, ``openimageio``, ``pycolmap``, ``bpy``,
    ``mitsuba``, ``matplotlib``), each under its own key; ``memory_total_gib``,
    ``memory_available_gib_at_start`` (GiB, 2 decimals); ``load_average_1_5_15_at_start``
    (``os.getloadavg()``); ``threads`` (the BLAS/OpenMP pinning variables, None when
    unset); ``note`` if given (what else ran on the machine).
    """
    info = {"cpu_count": os.cpu_count(), "platform": platform.platform(),
            "python": platform.python_version(), **package_versions(),
            "memory_total_gib": round(meminfo_bytes("MemTotal") / GIB, 2),
            "memory_available_gib_at_start": round(meminfo_bytes("MemAvailable") / GIB, 2),
            "load_average_1_5_15_at_start": list(os.getloadavg()),
            "threads": {k: os.environ.get(k) for k in THREAD_VARIABLES}}
    if note:
        info["note"] = note
    return info


def machine_end(info: dict) -> dict:
    """Add ``load_average_1_5_15_at_end`` to a :func:`machine` description; returns it."""
    info["load_average_1_5_15_at_end"] = list(os.getloadavg())
    return info


# --------------------------------------------------------------------------- results


def _git(*args: str) -> str | None:
    try:
        done = subprocess.run(["git", "-C", str(ROOT), *args], capture_output=True,
                              text=True, timeout=30)
    except (OSError, subprocess.SubprocessError):
        return None
    return done.stdout.strip() if done.returncode == 0 else None


def _plain(value):
    """``value`` as JSON-ready data (paths and other objects as strings)."""
    if isinstance(value, dict):
        return {str(k): _plain(v) for k, v in value.items()}
    if isinstance(value, list | tuple):
        return [_plain(v) for v in value]
    if value is None or isinstance(value, bool | int | float | str):
        return value
    return str(value)


def invocation(arguments=None) -> dict:
    """How this process was started: ``command`` (the interpreter and ``sys.argv``,
    shell-quoted, ready to paste), ``python``, ``argv``, ``cwd``, ``arguments`` (an
    ``argparse.Namespace`` or dict: the values the script used, defaults included),
    ``environment`` (the :data:`ENVIRONMENT` variables that are set), ``git_commit``
    and ``git_tracked_changes`` (whether tracked files differed from that commit)."""
    if isinstance(arguments, argparse.Namespace):
        arguments = vars(arguments)
    status = _git("status", "--porcelain", "--untracked-files=no")
    return {"command": shlex.join([sys.executable, *sys.argv]),
            "python": sys.executable, "argv": list(sys.argv), "cwd": os.getcwd(),
            "arguments": _plain(arguments),
            "environment": {k: os.environ[k] for k in ENVIRONMENT if k in os.environ},
            "git_commit": _git("rev-parse", "HEAD"),
            "git_tracked_changes": None if status is None else bool(status)}


def write_json(path, document: dict, *, arguments=None, invocation_key: str = "invocation",
               indent: int = 1) -> pathlib.Path:
    """Write ``document`` as JSON to ``path`` (a result file, normally under
    ``bench/results/``), with ``document[invocation_key] =`` :func:`invocation`
    ``(arguments)`` added (a script that updates part of an earlier file, such as
    ``--speed-only``, names its own key so the full run's record stays). Written to a
    temporary name in the same folder, then ``os.replace``d into place. Returns
    the path."""
    path = pathlib.Path(path)
    document[invocation_key] = invocation(arguments)
    text = json.dumps(document, indent=indent) + "\n"
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_name(f".{path.name}.{os.getpid()}.tmp")
    try:
        tmp.write_text(text)
        os.replace(tmp, path)
    finally:
        tmp.unlink(missing_ok=True)
    return path


# --------------------------------------------------------------------------- set-up


def heldout_spec(name: str) -> dict:
    """The held-out material ``name`` of ``core.brdf.database.heldout_specs``
    (KeyError naming the choices if there is none)."""
    from brdf_reconstruct.core.brdf import database

    specs = {s["name"]: s for s in database.heldout_specs()}
    if name not in specs:
        raise KeyError(f"unknown held-out material {name!r}; choose from {', '.join(specs)}")
    return specs[name]


def ensure_capture(material: str, views: int = DEMO_CAPTURE["views"],
                   lit: int = DEMO_CAPTURE["lit"], resolution=DEMO_CAPTURE["resolution"],
                   seed: int = DEMO_CAPTURE["seed"]) -> tuple[pathlib.Path, float | None]:
    """The capture of ``material`` with these settings (``testkit.capture``: the demo's
    cache, ``capture.cache_folder``), generated now in a fresh process if its
    ``job.toml`` is missing. Returns (folder, seconds the generation took, or None
    when it was cached)."""
    from testkit import capture

    settings = (material, views, lit, tuple(resolution), seed)
    folder = capture.cache_folder(*settings)
    if (folder / "job.toml").is_file():
        return folder, None
    t0 = time.perf_counter()
    subprocess.run(capture.command(folder, *settings), check=True, stdout=subprocess.DEVNULL)
    return folder, time.perf_counter() - t0


def run_batch(job, env: dict | None = None) -> tuple[subprocess.CompletedProcess, float,
                                                   float]:
    """``python -m brdf_reconstruct.brdf_addon.batch job`` in a fresh subprocess, as a
    user runs it (output captured as text), with ``env`` added to this process's
    environment. Returns (the finished process, its wall seconds, the 1-minute load
    average at its start)."""
    load = os.getloadavg()[0]
    t0 = time.perf_counter()
    done = subprocess.run([sys.executable, "-m", "brdf_reconstruct.brdf_addon.batch",
                           str(job)], capture_output=True, text=True,
                          env={**os.environ, **(env or {})})
    return done, time.perf_counter() - t0, load


def listed(value: str, allowed, flag: str) -> list[str] | None:
    """The comma-separated names of a command-line ``flag``, all of ``allowed``; None
    after one ``error:`` line on stderr when it names none or another."""
    names = [n for n in value.split(",") if n]
    if not names or set(names) - set(allowed):
        print(f"error: {flag} must name some of {', '.join(allowed)}", file=sys.stderr)
        return None
    return names


def measured_pack_or_error():
    """The measured pack (``testkit.measured.PACK``) loaded, or None after one
    ``error:`` line when it is not there."""
    from brdf_reconstruct.core.brdf import nbrdf
    from testkit import measured

    if not measured.PACK.is_file():
        print(f"error: {measured.PACK} not found (set BRDF_SHARED_DATA)", file=sys.stderr)
        return None
    return nbrdf.load(measured.PACK)


def measured_basis_without(pack, held):
    """The measured basis of the pack's materials not in ``held`` (a cross-validation
    fold's), listing them in ``info["materials"]``; built now, never cached (the
    cross-validation bench times the builds)."""
    from brdf_reconstruct.core.brdf import basis, nbrdf

    train = [n for n in pack.names if n not in held]
    makers = [functools.partial(nbrdf.valid_values, pack, pack.index(n)) for n in train]
    return basis.build_from(makers, names=train)


# ------------------------------------------------------------ held-out materials


def save_figure(fig, path) -> None:
    """Lay out, write (110 dpi) and close a bench's matplotlib figure."""
    import matplotlib.pyplot as plt

    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def log_boxplot(ax, data, labels, ylabel: str, title: str, label_size=None) -> None:
    """One panel of boxes on a log axis: ``data`` a list of value lists, one box each,
    named by ``labels``; the photo-pipeline benches' per-mode and per-scan panels."""
    ax.boxplot(data)
    ax.set_xticks(range(1, len(labels) + 1), labels, fontsize=label_size)
    ax.set_yscale("log")
    ax.set_ylabel(ylabel)
    ax.set_title(title, fontsize=9)


PIPELINE_OBJECTS = ("bunny", "spot")


def pipeline_bench_arguments(doc: str, argv, default_seeds: int, quick_help: str):
    """Parse a photo-pipeline bench's ``--seeds S``, ``--objects bunny,spot`` and
    ``--quick``. Returns ``(args, objects)``, or ``(None, exit status)`` after one
    error line (2: a bad argument, 1: the measured pack is missing)."""
    import argparse

    parser = argparse.ArgumentParser(description=doc,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--seeds", type=int, default=default_seeds,
                        help=f"seeds 0 to S - 1 (default {default_seeds})")
    parser.add_argument("--objects", default=",".join(PIPELINE_OBJECTS),
                        help="of bunny, spot")
    parser.add_argument("--quick", action="store_true", help=quick_help)
    args = parser.parse_args(argv)
    if args.seeds < 1:
        print("error: --seeds must be at least 1", file=sys.stderr)
        return None, 2
    objects = listed(args.objects, PIPELINE_OBJECTS, "--objects")
    if objects is None:
        return None, 2
    if measured_pack_or_error() is None:
        return None, 1
    return args, objects


def pipeline_materials(quick: bool = False) -> list[str]:
    """The held-out materials the photo-pipeline benches score: the 12 analytic ones
    and one measured material per class (``testkit.measured.one_per_class``);
    ``quick``: the first 3 and 2."""
    from brdf_reconstruct.core.brdf import database, nbrdf
    from testkit import measured

    analytic = [s["name"] for s in database.heldout_specs()]
    drawn = measured.one_per_class(nbrdf.load(measured.PACK).names)
    return analytic[:3] + drawn[:2] if quick else analytic + drawn


def is_measured(name: str) -> bool:
    """True for a material of the measured pack, False for an analytic held-out one
    (``heldout_*`` of ``core.brdf.database.heldout_specs``)."""
    return not name.startswith("heldout_")


def heldout_table(name: str):
    """The true table (3, 90, 90, 180) of a held-out material: an analytic one by its
    spec (:func:`heldout_spec`) or a measured one of the pack (``testkit.measured.PACK``),
    tabulated."""
    from brdf_reconstruct.core.brdf import database, nbrdf
    from testkit import measured

    if not is_measured(name):
        return database.make_table(heldout_spec(name))
    pack = nbrdf.load(measured.PACK)
    return nbrdf.tabulate(pack, pack.index(name))


def default_basis_without(name: str, n_components: int | None = None):
    """The shipped default basis (measured) that has not seen ``name``: for an
    analytic held-out material the whole bundled pack (``basis.load_measured()``,
    which holds no analytic material); for a measured one the pack's materials
    outside the cross-validation fold that holds it (``measured.fold_training``,
    5 folds; built once and cached like every basis), with ``n_components``
    (default ``basis.N_COMPONENTS``). Checked with ``measured.held_out``."""
    from brdf_reconstruct.core.brdf import basis, nbrdf
    from testkit import measured

    k = basis.N_COMPONENTS if n_components is None else n_components
    if not is_measured(name):
        B = _measured_basis(None, k)
    else:
        names = nbrdf.load(measured.PACK).names
        B = _measured_basis(tuple(measured.fold_training(names, name)), k)
    measured.held_out(B, name)
    return B


@functools.lru_cache(maxsize=8)
def _measured_basis(names: tuple[str, ...] | None, n_components: int):
    """``basis.load_measured`` of the bundled pack (``names`` None) or of the shared
    pack's ``names``, loaded once per process: the 12 analytic materials of a bench
    share one basis instead of holding 12 copies (about 0.2 GB each)."""
    from brdf_reconstruct.core.brdf import basis
    from testkit import measured

    if names is None:
        return basis.load_measured(n_components=n_components)
    return basis.load_measured(measured.PACK, names=names, n_components=n_components)
