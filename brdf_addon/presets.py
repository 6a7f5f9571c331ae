"""The Fast / Balanced / Accurate presets: values of the panel's and job file's settings.

Plain data (no bpy), so the benchmark that measures them (``bench/tradeoff.py``,
``bench/results/tradeoff.json``) runs exactly these values. PROVISIONAL until
that benchmark sets them.
"""

PRESETS = {
    "FAST": dict(samples=6, trials=4, subset_fraction=0.5, kl_path="FAST", kl_samples=16),
    "BALANCED": dict(samples=20, trials=16, subset_fraction=0.5, kl_path="FAST",
                     kl_samples=16),
    "ACCURATE": dict(samples=40, trials=32, subset_fraction=0.5, kl_path="CYCLES",
                     kl_samples=16),
}
