"""The Fast / Balanced / Accurate presets: values of the panel's and job file's settings.

Plain data (no bpy), so that the benchmark that measured them
(``bench/tradeoff.py``, ``bench/results/tradeoff.json``, "presets") runs exactly
these values. Chosen from that benchmark's sweep on the blunted bunny capture
and from the held-out comparison (README, "The speed/accuracy trade"):

- trials buy little beyond 4 with the fast selection, so Fast uses 4;
- 20 condition-optimal samples per trial: the paper's 6 did better on the two
  sweep materials but worse over the 12 held-out materials (median sphere error
  0.49 against 0.40, ``bench/results/heldout_samples6.json``);
- the Cycles selection path picked better trials than the numpy one on both
  sweep materials, at about 10x the time; its ranking is the same from 4 to 64
  Cycles samples, and 16 keeps a margin against render noise.
"""

PRESETS = {
    "FAST": dict(samples=20, trials=4, subset_fraction=0.5, kl_path="FAST", kl_samples=16),
    "BALANCED": dict(samples=20, trials=16, subset_fraction=0.5, kl_path="FAST",
                     kl_samples=16),
    "ACCURATE": dict(samples=20, trials=16, subset_fraction=0.5, kl_path="CYCLES",
                     kl_samples=16),
}
