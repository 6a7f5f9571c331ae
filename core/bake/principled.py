"""The Principled BSDF version of a bake (issue 16): what Eevee, the glTF exporter and
other engines read, since they do not read the "BRDF Reconstruction" node group.

The Principled BSDF cannot take the bake's closures one for one (it has one
specular lobe, a coat and a sheen, and its Fresnel follows the IOR), so its
parameters are derived from the lobe fit (``core.bake.lobes.LobeParams``):

- **metal or dielectric**: a metal when the fit has almost no diffuse (its mean
  below ``METAL_DIFFUSE`` x its lobes' mean colours), as conductors do;
- **base color**: the Lambert albedo (dielectric) or the specular lobe's colour
  (below), its reflectance at normal incidence (metal), clipped to [0, 1];
- **one specular lobe**: a metal's lobes all together, a dielectric's main lobe
  (the largest mean colour) with those whose alpha is within
  ``SAME_LOBE_ALPHA_RATIO`` of its own (a fit may split one lobe in two): their
  colours summed, their alphas' geometric mean weighted by their mean colours;
- **roughness**: that lobe's, ``sqrt(alpha)``; a Beckmann lobe first becomes its
  closest GGX (:func:`ggx_like_beckmann`: alpha and colour scale), since the
  Principled BSDF has only GGX;
- **specular** (dielectric): the main lobe's mean colour is the normal-incidence
  reflectance F0; IOR 1.5 and ``Specular IOR Level = F0 / 0.08`` (0.5 gives the
  IOR's own 0.04; 1 doubles it); above 0.08 the level 1 and the IOR whose doubled
  F0 it is; the tint the colour over its mean;
- **coat**: a dielectric's strongest lobe of another roughness, its weight its
  mean colour over the coat's F0 at IOR 1.5 (0.04), clipped to 1, its roughness
  the lobe's;
- **sheen**: the velvet's colour as weight (its largest channel) and tint, its
  roughness the velvet's sigma.

It is an approximation by design; its error against the table is measured in
Cycles like the node group's (``brdf_addon.material.bake_error``), and reported
beside it. Cycles' Principled BSDF is set to single-scattering GGX, like the bake.
"""

from __future__ import annotations

import dataclasses
import functools

import numpy as np

from . import lobes

METAL_DIFFUSE = 0.05  # a fit whose diffuse is below this share of its lobes is a metal
SAME_LOBE_ALPHA_RATIO = 2.0  # lobes whose alphas are within this factor act as one
_F0_IOR_1_5 = 0.04  # ((1.5 - 1) / (1.5 + 1))^2
_LEVEL_PER_F0 = 0.5 / _F0_IOR_1_5  # Specular IOR Level 0.5 is the IOR's own F0


@dataclasses.dataclass(frozen=True)
class PrincipledParams:
    """The Principled BSDF's inputs (Blender 4.0+ names in ``to_inputs``): base_color
    (3,), metallic, roughness, ior, specular_level, specular_tint (3,), coat_weight,
    coat_roughness, sheen_weight, sheen_roughness, sheen_tint (3,); all finite, colours
    and factors in [0, 1]."""

    base_color: tuple
    metallic: float
    roughness: float
    ior: float = 1.5
    specular_level: float = 0.5
    specular_tint: tuple = (1.0, 1.0, 1.0)
    coat_weight: float = 0.0
    coat_roughness: float = 0.03
    sheen_weight: float = 0.0
    sheen_roughness: float = 0.5
    sheen_tint: tuple = (1.0, 1.0, 1.0)

    def to_inputs(self) -> dict:
        """{Principled BSDF input name: value} (colours as RGBA)."""
        def rgba(c):
            return (*(float(x) for x in c), 1.0)

        return {
            "Base Color": rgba(self.base_color), "Metallic": float(self.metallic),
            "Roughness": float(self.roughness), "IOR": float(self.ior),
            "Specular IOR Level": float(self.specular_level),
            "Specular Tint": rgba(self.specular_tint),
            "Coat Weight": float(self.coat_weight), "Coat Roughness": float(self.coat_roughness),
            "Coat IOR": 1.5, "Sheen Weight": float(self.sheen_weight),
            "Sheen Roughness": float(self.sheen_roughness), "Sheen Tint": rgba(self.sheen_tint),
        }

    def to_dict(self) -> dict:
        return {k: (list(v) if isinstance(v, tuple) else v)
                for k, v in dataclasses.asdict(self).items()}


def _unit(x) -> float:
    return float(np.clip(np.nan_to_num(x), 0.0, 1.0))


def _colour(c) -> tuple:
    return tuple(float(x) for x in np.clip(np.nan_to_num(np.asarray(c, dtype=np.float64)),
                                           0.0, 1.0))


def _pairs(alpha: float, n: int = 48) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(light, view, weight) where a lobe of ``alpha`` lives, local frame: views at
    0, 30 and 60 degrees; half vectors on an n x n polar grid out to tan theta_h =
    8 alpha (the lobe's width is about alpha in tan theta_h), the light their
    mirror of the view; weight the light's solid angle (4 v.h dOmega_h), so that a
    sum over the pairs is an integral over light directions."""
    top = np.arctan(min(8.0 * alpha, 50.0))
    theta = (np.arange(n) + 0.5) / n * top
    phi = (np.arange(2 * n) + 0.5) / (2 * n) * 2.0 * np.pi
    t, f = np.meshgrid(theta, phi, indexing="ij")
    h = np.stack([np.sin(t) * np.cos(f), np.sin(t) * np.sin(f), np.cos(t)], -1).reshape(-1, 3)
    d_omega_h = (np.sin(t) * (top / n) * (np.pi / n)).reshape(-1)
    lights, views, weights = [], [], []
    for angle in np.radians([0.0, 30.0, 60.0]):
        v = np.array([np.sin(angle), 0.0, np.cos(angle)])
        vh = h @ v
        light = 2.0 * vh[:, None] * h - v
        ok = (light[:, 2] > 1e-6) & (vh > 0.0)
        lights.append(light[ok])
        views.append(np.broadcast_to(v, light[ok].shape))
        weights.append(4.0 * vh[ok] * d_omega_h[ok])
    return np.concatenate(lights), np.concatenate(views), np.concatenate(weights)


@functools.lru_cache(maxsize=256)
def ggx_like_beckmann(alpha: float) -> tuple[float, float]:
    """(alpha, scale) of the GGX lobe closest to a Beckmann lobe of ``alpha``: the
    least-squares match of their radiance (BRDF x cos theta_l, ``lobes.evaluate``)
    integrated over light directions where the lobe lives (:func:`_pairs`), the
    scale fitted for each GGX alpha and the alpha by a bounded search in log alpha.
    The Principled BSDF has only GGX; a Beckmann lobe taken at its own alpha has
    other tails (copper's bake error 0.23)."""
    from scipy.optimize import minimize_scalar

    light, view, weight = _pairs(alpha)

    def radiance(dist, a):
        lobe = lobes.LobeParams.build(lobes=[(dist, (1.0, 1.0, 1.0), 0.0, a)])
        return lobes.evaluate(lobe, light, view)[:, 0] * light[:, 2]

    target = radiance("beckmann", alpha)

    def fit(log_a):
        g = radiance("ggx", float(np.exp(log_a)))
        k = float(np.sum(weight * g * target)) / max(float(np.sum(weight * g * g)), 1e-300)
        return float(np.sum(weight * (k * g - target) ** 2)), k

    lo, hi = np.log(max(alpha / 4.0, lobes.ALPHA_MIN)), np.log(min(alpha * 4.0, 1.0))
    best = minimize_scalar(lambda x: fit(x)[0], method="bounded", bounds=(lo, hi),
                           options={"xatol": 1e-4})
    return float(np.exp(best.x)), fit(best.x)[1]


def from_lobes(params) -> PrincipledParams:
    """The Principled BSDF's parameters for a lobe fit (see the module docstring).
    params: :class:`core.bake.lobes.LobeParams` or its dict."""
    p = params if isinstance(params, lobes.LobeParams) else lobes.LobeParams.from_dict(params)
    kd = np.asarray(p.diffuse, dtype=np.float64)
    sheen = {}
    if np.any(p.sheen > 0.0):
        peak = float(np.max(p.sheen))
        sheen = dict(sheen_weight=_unit(peak), sheen_roughness=_unit(p.sheen_sigma),
                     sheen_tint=_colour(p.sheen / max(peak, 1e-12)))
    if len(p.alphas) == 0:  # diffuse only: no specular at all
        return PrincipledParams(base_color=_colour(kd), metallic=0.0, roughness=0.5,
                                specular_level=0.0, **sheen)
    colors, alphas = np.array(p.colors, dtype=np.float64), np.array(p.alphas, dtype=np.float64)
    for k, dist in enumerate(p.distributions):  # the Principled BSDF's GGX for a Beckmann
        if dist == "beckmann":
            alphas[k], scale = ggx_like_beckmann(round(float(alphas[k]), 4))
            colors[k] *= scale
    strength = np.maximum(colors.mean(axis=1), 0.0)
    main = int(np.argmax(strength))
    metal = kd.mean() < METAL_DIFFUSE * max(float(strength.sum()), 1e-12)
    # one lobe: a metal's every lobe (it has no coat), else the main lobe and those of
    # nearly its roughness (a fit may split one lobe in two: gold's 0.30 and 0.64 at
    # alpha 0.12 lost a third of its energy as the main lobe alone)
    same = np.ones(len(alphas), bool) if metal else (
        np.abs(np.log(alphas / alphas[main])) <= np.log(SAME_LOBE_ALPHA_RATIO))
    colour = colors[same].sum(axis=0)
    weights = strength[same] if strength[same].sum() > 0.0 else np.ones(int(same.sum()))
    alpha = float(np.exp(np.average(np.log(alphas[same]), weights=weights)))
    roughness = _unit(np.sqrt(alpha))
    f0 = float(max(colour.mean(), 0.0))
    if metal:
        return PrincipledParams(base_color=_colour(colour), metallic=1.0, roughness=roughness,
                                **sheen)
    coat = {}
    if not same.all():
        other = int(np.argmax(np.where(same, -np.inf, strength)))
        coat = dict(coat_weight=_unit(strength[other] / _F0_IOR_1_5),
                    coat_roughness=_unit(np.sqrt(alphas[other])))
    tint = colour / max(f0, 1e-12)
    ior, level = 1.5, f0 * _LEVEL_PER_F0
    if level > 1.0:  # Specular IOR Level 1 doubles the IOR's F0: the IOR that gives f0
        r = min(np.sqrt(f0 / 2.0), 0.95)
        ior, level = float((1.0 + r) / (1.0 - r)), 1.0
    return PrincipledParams(base_color=_colour(kd), metallic=0.0, roughness=roughness,
                            ior=ior, specular_level=_unit(level),
                            specular_tint=_colour(tint / max(np.max(tint), 1.0)), **coat, **sheen)
