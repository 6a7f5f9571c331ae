"""The Fast / Balanced / Accurate / Paper presets: values of the panel's and job file's
settings.

Plain data (no bpy), so that the benchmark that measured them
(``bench/tradeoff.py``, ``bench/results/tradeoff.json``, "presets") runs exactly
these values. Chosen from that benchmark's sweep on the blunted bunny capture
and from the held-out comparison (docs/results.md, "The speed/accuracy trade"):

- trials (sweep rerun 2026-12-04 on the current defaults, four materials x 2
  seeds): 1 trial 0.391, 4 trials 0.304, 16 trials 0.277, 64 trials 0.283, so
  Fast uses 4 and Balanced 16;
- 20 condition-optimal samples per trial: the paper's 6 had the lower median on
  the sweep's four (0.254) but was worse on the gold and the plastic, and worse
  over the 19 held-out materials (median sphere error 0.500 against 0.482, lower
  on 4 of 19; ``bench/tradeoff.py --part heldout``,
  ``bench/results/tradeoff_heldout.json``); 80 samples 0.318; neither more
  pixels (480 x 360: 0.336) nor more components (80: 0.277) buy anything;
- the Cycles selection path (the candidate tables rendered) picks Balanced's
  trial for three of the four materials and a better one for the rough plastic
  (0.060 against 0.071), the same median at about 5x the time; 4, 16 and 64
  Cycles samples pick alike, so Accurate renders with 4.

Paper is not a point of that trade but the paper's own mode, kept so that its
result stays reproducible and for the ablation (issue 15): 6 samples per trial
(Ono et al. 2017, Sec. 4.1: "used six pairs of lights and view directions as the
optimal directions"), 16 trials (the paper says only "several times", Sec. 3.2),
half the reliable pixels per trial (the paper gives no share), and the Cycles
selection, since the paper renders each candidate and compares the KL of the
intensity histograms (Sec. 3.2); Cycles samples as Accurate's.

Every preset but Paper keeps the highlights' energy (``keep_highlight_energy``,
``core.method.refine.energy_consistent``, added 2026-12-04): the chosen trial
refitted so each photo's radiance sum is kept. On the 19 held-out materials
(3 seeds, ``bench/photo_bench.py``, docs/results.md) it took Balanced's median
sphere error from 0.397 to 0.280 on the degraded bunny, 0.668 to 0.534 on
degraded Spot, and 0.234 to 0.150 and 0.196 to 0.158 on their exact scans. The
paper's method has no such step.

Accurate models each photo pixel's footprint (``pixel_footprint``, added 2026-12-07: the
scan's normals at 2 x 2 points per pixel, read by the refits to every pixel); the others
do not. Measured through the extension on Cycles-rendered photos
(``bench/footprint_bench.py``, six held-out materials, seed 0): on the exact-normal
scans the median sphere error 0.126 -> 0.104 (bunny) and 0.134 -> 0.081 (Spot), on the
degraded ones 0.146 -> 0.144 and 0.369 -> 0.369, for about 1.3 to 2.1 s more per run
(a second G-buffer render per photo, and the refits' pixel predictions made four
times). In Balanced that time broke issue 15's 5 s for the demo's batch run (6.10 s
against 4.5 to 5 s without, best of 3) and bought nothing on a blunted scan, so it
stays off there: turn it on for an accurate scan. The paper reads each pixel at its
centre and has no refit.

Choosing a preset in the panel sets these values; setting one of them to another
value afterwards (in the panel or a job file) makes the preset Custom
(``brdf_addon.props``, the ``update`` callbacks).
"""

PRESETS = {
    "FAST": dict(samples=20, trials=4, subset_fraction=0.5, kl_path="FAST", kl_samples=16,
                 keep_highlight_energy=True, pixel_footprint=False),
    "BALANCED": dict(samples=20, trials=16, subset_fraction=0.5, kl_path="FAST",
                     kl_samples=16, keep_highlight_energy=True, pixel_footprint=False),
    "ACCURATE": dict(samples=20, trials=16, subset_fraction=0.5, kl_path="CYCLES",
                     kl_samples=4, keep_highlight_energy=True, pixel_footprint=True),
    "PAPER": dict(samples=6, trials=16, subset_fraction=0.5, kl_path="CYCLES", kl_samples=4,
                  keep_highlight_energy=False, pixel_footprint=False),
}

# One line per preset for the panel and tooltips: what it costs and buys, as measured
# (bench/results/tradeoff.json, "presets", 2026-12-04 evening, with the photos judging
# the refit, `bench/tradeoff.py --part presets`
# run on every entry of PRESETS, the default measured basis and the pipeline's default
# condition-number sampler: bunny capture, 3 photos of 240 x 180, wall seconds per
# region on a 2-core machine shared with other jobs, median rendered-sphere error over
# 2 analytic and 2 measured held-out materials x 2 seeds; docs/results.md). The
# tradeoff bench reads pixel centres; the footprint's time is bench/footprint_bench.py's
# and the demo capture's (docs/results.md, "The pixel footprint through the extension").
HINTS = {
    "FAST": "20 samples x 4 trials, numpy selection, judged refit: about 1.5 s, error 0.17",
    "BALANCED": "20 samples x 16 trials, numpy selection, judged refit: about 2 s, error 0.18",
    "ACCURATE": "20 samples x 16 trials, Cycles selection, judged refit: about 6 s, error 0.18; "
                "pixel footprint (accurate scans) about 1.5 s more",
    "PAPER": "The paper's method: 6 samples x 16 trials, Cycles selection: about 5 s, error 0.27",
}
