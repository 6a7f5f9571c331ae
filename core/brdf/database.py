"""The built-in database of tabulated analytic BRDFs, the training set of the basis.

The real MERL database cannot be downloaded here (METHOD.md §1), so the PCA
basis of Nielsen et al. (2015) is trained on analytic materials evaluated at
the MERL cell centres instead. Specs are plain JSON dicts (schema in
:mod:`models`); a table is ``(3, 90, 90, 180)`` float64 in 1/sr, NaN where a
cell centre has the light or the view below the horizon.

Two lists, both deterministic:

- :func:`training_specs`: 150 materials drawn with ``numpy.random.Generator``
  seeded by ``TRAINING_SEED``: Lambert, Oren-Nayar, plastics, metals (every
  entry of ``models.METALS``, rough to near-mirror, plain and tinted),
  clear-coated paints, fabrics and mixtures; albedo from about 1e-3 to 0.9,
  microfacet alpha from 0.005 to 1.
- :func:`heldout_specs`: hand-picked materials plus a few drawn with
  ``HELDOUT_SEED``, none equal to a training material, to measure
  reconstruction on materials the basis has not seen.
"""

from __future__ import annotations

import functools
import hashlib
import json
from pathlib import Path

import numpy as np

from . import merl, models
from .fresnel import METALS

TRAINING_SEED = 20170715
HELDOUT_SEED = 20151201
ALBEDO_RANGE = (1e-3, 0.9)
ALPHA_RANGE = (0.005, 1.0)


def make_table(spec):
    """Tabulate a material spec on the MERL grid.

    Parameters
    ----------
    spec : dict
        Material spec (see :mod:`models`).

    Returns
    -------
    table : ndarray, (3, 90, 90, 180), float64
        BRDF in 1/sr at each cell centre (``merl.cell_directions``), NaN where
        ``merl.valid_cells()`` is False.
    """
    table = np.full((3, merl.N_CELLS), np.nan)
    table[:, merl.valid_cells()] = valid_values(spec)
    return table.reshape(3, *merl.SHAPE)


def valid_values(spec):
    """A material spec at the valid cells only (``merl.valid_cells()``, in order):
    (3, n_valid) float64 in 1/sr, what :func:`make_table` holds there, without
    evaluating the cells below the horizon (a quarter of the grid)."""
    wi, wo, levels = _valid_directions()
    return np.ascontiguousarray(models.evaluate(spec, wi, wo, levels=levels).T)


@functools.lru_cache(maxsize=1)
def _valid_directions():
    """wi, wo (n_valid, 3) at the valid cells and their ``levels`` for
    ``models.evaluate``: the cosines of the 90 theta_h and 90 theta_d bin centres
    and each valid cell's bins."""
    valid = merl.valid_cells()
    wi, wo = merl.cell_directions()
    bins = np.indices(merl.SHAPE).reshape(3, -1)[:, valid]
    # cells (i, i, i): theta_h and theta_d have 90 bins each (the MERL format)
    diagonal = np.repeat(np.arange(merl.SHAPE[0]), 3).reshape(-1, 3)
    theta_h, theta_d, _ = merl.angles_from_cells(diagonal)
    levels = {"cos_h": (np.cos(theta_h), bins[0]), "cos_d": (np.cos(theta_d), bins[1])}
    return wi[valid], wo[valid], levels


def database_fingerprint(specs):
    """Stable hex digest of the specs and of the code that turns them into tables.

    Hashes the JSON of ``specs`` (sorted keys) and the source of ``models``,
    ``fresnel``, ``database`` and ``merl`` (which fixes the cell centres), so
    any change to a spec, a model or the grid invalidates a cached basis.
    Returns 32 hex characters (blake2b, 16-byte digest).
    """
    h = hashlib.blake2b(digest_size=16)
    h.update(json.dumps(specs, sort_keys=True, separators=(",", ":")).encode())
    here = Path(__file__).parent
    for name in ("models.py", "fresnel.py", "database.py", "merl.py"):
        h.update(b"\0" + name.encode() + b"\0")
        h.update((here / name).read_bytes())
    return h.hexdigest()


# --- building blocks ------------------------------------------------------------


def _r(x):
    """Round to 4 significant digits, as a plain float (readable, stable JSON)."""
    return float(f"{float(x):.4g}")


def _rgb(values):
    return [_r(v) for v in values]


def _log_uniform(rng, lo, hi):
    return float(np.exp(rng.uniform(np.log(lo), np.log(hi))))


def _colour(rng, level, saturation=None):
    """An RGB albedo whose largest channel is ``level``, random hue and saturation."""
    if saturation is None:
        saturation = rng.uniform(0.0, 0.9)
    hue = rng.uniform(0.2, 1.0, 3)
    c = 1.0 - saturation * (1.0 - hue / hue.max())
    return _rgb(level * c)


def _dist(rng):
    return "ggx" if rng.uniform() < 0.6 else "beckmann"


def _lambert(albedo):
    return {"type": "lambert", "albedo": albedo}


def _dielectric(eta):
    return {"type": "dielectric", "eta": _r(eta)}


def _metal(name):
    return {"type": "conductor", "metal": name}


def _microfacet(dist, alpha, fresnel, weight=None):
    lobe = {"type": dist, "alpha": _r(alpha), "fresnel": fresnel}
    if weight is not None:
        lobe["weight"] = weight
    return lobe


def _coat(dist, alpha, eta, weight=1.0):
    return {"distribution": dist, "alpha": _r(alpha), "eta": _r(eta), "weight": _r(weight)}


def _spec(name, category, lobes, coat=None):
    spec = {"name": name, "category": category, "lobes": lobes}
    if coat is not None:
        spec["coat"] = coat
    return spec


def _albedo_level(rng):
    return _log_uniform(rng, *ALBEDO_RANGE)


# --- the training set -------------------------------------------------------------


def training_specs():
    """The training materials: a list of 150 spec dicts with unique names.

    Deterministic: the same list on every call and machine (seeded Generator,
    values rounded to 4 significant digits).
    """
    rng = np.random.default_rng(TRAINING_SEED)
    specs = []

    def add(category, lobes, coat=None):
        specs.append(_spec(f"{category}_{len(specs):03d}", category, lobes, coat))

    # The extremes are pinned so the range is covered whatever the draws.
    add("lambert", [_lambert(_rgb([1e-3] * 3))])
    add("lambert", [_lambert(_rgb([0.9] * 3))])
    for _ in range(12):
        add("lambert", [_lambert(_colour(rng, _albedo_level(rng)))])

    for _ in range(12):
        add("oren_nayar", [{"type": "oren_nayar", "albedo": _colour(rng, _albedo_level(rng)),
                            "sigma": _r(rng.uniform(0.1, 1.2))}])

    # Plastics: a dielectric interface over a diffuse body, mostly layered
    # (the coat formula conserves energy), some as a plain sum of lobes.
    for i in range(30):
        body = [_lambert(_colour(rng, _albedo_level(rng)))]
        dist, alpha, eta = _dist(rng), _log_uniform(rng, *ALPHA_RANGE), rng.uniform(1.3, 1.8)
        if i % 3 == 2:
            add("plastic", body + [_microfacet(dist, alpha, _dielectric(eta))])
        else:
            add("plastic", body, _coat(dist, alpha, eta))

    # Metals: every metal at a rough, a medium and a near-mirror roughness.
    for name in sorted(METALS):
        for lo, hi in ((0.2, 1.0), (0.03, 0.2), (0.005, 0.03)):
            add("metal", [_microfacet(_dist(rng), _log_uniform(rng, lo, hi), _metal(name))])
    # Tinted metals (anodised, coloured coatings): conductor Fresnel times a tint,
    # or a coloured Schlick f0.
    for i in range(12):
        alpha = _log_uniform(rng, *ALPHA_RANGE)
        if i % 2 == 0:
            fresnel = _metal(str(rng.choice(sorted(METALS))))
            add("metal_tinted", [_microfacet(_dist(rng), alpha, fresnel,
                                             _colour(rng, 1.0, rng.uniform(0.2, 0.7)))])
        else:
            fresnel = {"type": "schlick", "f0": _colour(rng, rng.uniform(0.5, 0.95))}
            add("metal_tinted", [_microfacet(_dist(rng), alpha, fresnel)])

    # Clear-coated paints: a diffuse or metallic-flake base under a glossy coat.
    for i in range(18):
        base = [_lambert(_colour(rng, _albedo_level(rng), rng.uniform(0.3, 0.95)))]
        if i % 2 == 1:
            base.append(_microfacet(_dist(rng), rng.uniform(0.15, 0.5),
                                    _metal(str(rng.choice(["Al", "Ag", "Ni", "Cu", "Au"]))),
                                    _colour(rng, rng.uniform(0.2, 0.8))))
        add("paint", base, _coat(_dist(rng), _log_uniform(rng, 0.005, 0.1),
                                 rng.uniform(1.4, 1.6), rng.uniform(0.6, 1.0)))

    # Fabrics: a sheen over a diffuse or Oren-Nayar body.
    for i in range(18):
        level = _albedo_level(rng)
        body = _colour(rng, level, rng.uniform(0.2, 0.95))
        if i % 2 == 0:
            base = _lambert(body)
        else:
            base = {"type": "oren_nayar", "albedo": body, "sigma": _r(rng.uniform(0.3, 1.2))}
        sheen = {"type": "sheen", "roughness": _r(rng.uniform(0.25, 1.0)),
                 "color": _colour(rng, min(1.0, 3.0 * level) * rng.uniform(0.2, 1.0))}
        add("fabric", [base, sheen])

    # Mixtures: partly metallic surfaces, two-scale gloss (a haze), dusty gloss.
    for i in range(19):
        kind = i % 3
        if kind == 0:  # metal patches in a dielectric: weights sum to 1
            w = _r(rng.uniform(0.2, 0.8))
            name = str(rng.choice(sorted(METALS)))
            lobes = [_lambert(_colour(rng, (1.0 - w) * _albedo_level(rng))),
                     _microfacet(_dist(rng), _log_uniform(rng, 0.02, 0.5), _metal(name), w)]
            add("mixture", lobes)
        elif kind == 1:  # haze: a sharp and a broad lobe of the same metal
            name = str(rng.choice(sorted(METALS)))
            w = _r(rng.uniform(0.2, 0.8))
            lobes = [_microfacet("ggx", _log_uniform(rng, 0.005, 0.05), _metal(name), w),
                     _microfacet("ggx", _log_uniform(rng, 0.1, 0.6), _metal(name), _r(1 - w))]
            add("mixture", lobes)
        else:  # diffuse + rough Oren-Nayar dust + a dielectric gloss
            lobes = [{"type": "oren_nayar", "albedo": _colour(rng, 0.5 * _albedo_level(rng)),
                      "sigma": _r(rng.uniform(0.2, 1.0))},
                     _lambert(_colour(rng, 0.5 * _albedo_level(rng))),
                     _microfacet(_dist(rng), _log_uniform(rng, 0.05, 0.5),
                                 _dielectric(rng.uniform(1.3, 1.8)))]
            add("mixture", lobes)
    return specs


# --- held-out materials -----------------------------------------------------------


def heldout_specs():
    """Held-out materials, never in :func:`training_specs`: 12 specs, names "heldout_*".

    Eight are hand-picked to cover the cases reconstruction must handle; four
    more are drawn with their own seed (``HELDOUT_SEED``).
    """
    specs = [
        _spec("heldout_silver_mirror", "metal",
              [_microfacet("ggx", 0.013, _metal("Ag"))]),
        _spec("heldout_aluminium_polished", "metal",
              [_microfacet("ggx", 0.0185, _metal("Al"))]),
        _spec("heldout_near_black", "plastic",
              [_lambert([0.0011, 0.0012, 0.0013]),
               _microfacet("ggx", 0.0777, _dielectric(1.47), 0.5)]),
        _spec("heldout_rough_plastic", "plastic",
              [_lambert([0.52, 0.21, 0.09])], _coat("ggx", 0.31, 1.51)),
        _spec("heldout_glossy_plastic", "plastic",
              [_lambert([0.05, 0.17, 0.43])], _coat("beckmann", 0.043, 1.49)),
        _spec("heldout_gold_medium", "metal",
              [_microfacet("ggx", 0.123, _metal("Au"))]),
        _spec("heldout_fabric", "fabric",
              [{"type": "oren_nayar", "albedo": [0.33, 0.06, 0.08], "sigma": 0.77},
               {"type": "sheen", "color": [0.55, 0.31, 0.33], "roughness": 0.61}]),
        _spec("heldout_coated_paint", "paint",
              [_lambert([0.04, 0.11, 0.27]),
               _microfacet("ggx", 0.27, _metal("Al"), [0.31, 0.38, 0.47])],
              _coat("ggx", 0.0123, 1.52, 0.93)),
        _spec("heldout_lambert_grey", "lambert", [_lambert([0.18, 0.18, 0.18])]),
    ]
    rng = np.random.default_rng(HELDOUT_SEED)
    specs.append(_spec("heldout_random_plastic", "plastic",
                       [_lambert(_colour(rng, _albedo_level(rng)))],
                       _coat(_dist(rng), _log_uniform(rng, *ALPHA_RANGE), rng.uniform(1.3, 1.8))))
    specs.append(_spec("heldout_random_copper", "metal",
                       [_microfacet(_dist(rng), _log_uniform(rng, 0.02, 0.4), _metal("Cu"))]))
    specs.append(_spec("heldout_random_fabric", "fabric",
                       [_lambert(_colour(rng, _albedo_level(rng))),
                        {"type": "sheen", "color": _colour(rng, 0.5),
                         "roughness": _r(rng.uniform(0.25, 1.0))}]))
    return specs
