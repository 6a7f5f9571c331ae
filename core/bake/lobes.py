"""The bake's model: lobes Cycles renders exactly, evaluated and tabulated in numpy.

Cycles has no tabulated-BRDF closure (METHOD.md §8), so for relighting under any
light the table is baked into a small model made of standard Cycles closures,
added together (``brdf_addon/material.py`` builds the nodes)::

    rho(l, v) = kd / pi
              + sum_k [A_k + B_k (1 - l.h)^5] D(h; a_k) G2(l, v; a_k) / (4 cos_l cos_v)
              + C D_v(h; sigma) G_v(l, v) / (4 cos_l cos_v)

- ``kd``: RGB >= 0, a Diffuse BSDF (roughness 0 = Lambert) with Color kd.
- ``A_k``: RGB >= 0, a Glossy BSDF (distribution GGX or Beckmann, per lobe),
  Color A_k: Cycles multiplies the closure by the colour (not clamped) and
  applies no Fresnel.
- ``B_k``: grey, in [0, 1], a Metallic BSDF (Fresnel "F82", Base Color black,
  Edge Tint white, so F = (1 - l.h)^5, Schlick with F0 = 0) behind a Mix Shader
  with factor B_k: the rise to white at grazing angles that every Fresnel has.
- ``D``: GGX ``a^2 / (pi (1 - c^2 + a^2 c^2)^2)`` or Beckmann
  ``exp(-tan^2 / a^2) / (pi a^2 c^4)``, c = n.h.
- ``G2``: height-correlated Smith, ``1 / (1 + Lambda_l + Lambda_v)``; GGX:
  ``Lambda = (sqrt(1 + a^2 tan^2) - 1) / 2``; Beckmann: Cycles' rational
  approximation in ``x = 1 / (a tan)``, ``(1 - 1.259 x + 0.396 x^2) /
  (3.535 x + 2.181 x^2)``, 0 for ``x >= 1.6`` (Walter et al. 2007).
- ``a_k = roughness_k^2`` with roughness clamped to [0, 1] by Cycles; here
  ``a`` in [ALPHA_MIN, 1].
- ``C``: RGB >= 0, a Sheen BSDF with distribution "Ashikhmin" (Cycles' velvet
  closure) and Roughness sigma in [SIGMA_MIN, 1]: ``D_v = exp(-cot^2 / sigma^2) /
  (pi sigma^2 sin^4)`` of the half vector's angle, ``G_v = min(1, 2 (n.h / l.h)
  cos_v, 2 (n.h / l.h) cos_l)``; zero when ``n.h >= 1 - 1e-5``. It gives the
  rim brightening of cloth that no GGX lobe can.

This is Cycles' ``bsdf_microfacet_eval<GGX or BECKMANN>`` (it returns the BRDF
times the light cosine) after ``bsdf_microfacet_ggx_setup`` /
``..._beckmann_setup`` (``energy_scale = 1``: the energy compensation is only
for "Multiscatter GGX"), with Fresnel NONE for the
Glossy BSDF and ``fresnel_f82`` with ``B = 0`` (white tint) for the Metallic
BSDF, and ``alpha = sqr(saturate(Roughness))`` in the SVM closure node; the
velvet is ``bsdf_ashikhmin_velvet_eval`` with ``sigma = max(saturate(Roughness),
0.01)`` (Cycles ``kernel/closure/bsdf_microfacet.h``, ``bsdf_util.h``,
``bsdf_ashikhmin_velvet.h``, ``kernel/svm/closure.h``, Blender 4.x-5.x).
``tests/blender/test_material.py`` checks it against Cycles renders. The
Principled BSDF is not the target: it scales its diffuse base by the specular
layer's albedo from Cycles' lookup tables, which numpy cannot reproduce exactly.

The fit of this model to a table is :mod:`.fitting`.
"""

from __future__ import annotations

import dataclasses
import functools

import numpy as np

from ..brdf import merl

ALPHA_MIN = 1e-3  # roughness 0.032; MERL's first theta_h bins resolve lobes this sharp
ALPHA_MAX = 1.0  # roughness 1, Cycles' clamp
SIGMA_MIN = 0.05  # velvet width; sharper ones only light the last degree before grazing
SIGMA_MAX = 1.0
DISTRIBUTIONS = ("ggx", "beckmann")  # the Glossy BSDF's "GGX" and "BECKMANN"
MAX_LOBES = 2
INV_PI = 1.0 / np.pi
_VELVET_COS_H_MAX = 1.0 - 1e-5  # Cycles returns 0 above this n.h (and for l.h <= 1e-5)
_SINGULAR_ALPHA2 = 2e-10  # Cycles' BSDF_ROUGHNESS_SQ_THRESH: smoother lobes are not evaluated
INV_PI = INV_PI
_BLOCK = 32768  # rows per block of evaluate and tabulate


# ----------------------------------------------------------------------------- params
@dataclasses.dataclass(frozen=True, eq=False)  # arrays: no element-wise ==
class LobeParams:
    """Parameters of the Cycles-renderable model (see the module docstring).

    diffuse: (3,) Lambert albedo kd. colors: (K, 3) Glossy colours A_k.
    grazing: (K,) Fresnel rise B_k in [0, 1]. alphas: (K,) microfacet widths
    a_k = roughness^2 in [ALPHA_MIN, 1]. sheen: (3,) velvet colour C (zeros
    for none). sheen_sigma: velvet roughness in [SIGMA_MIN, 1]. float64, finite.
    distributions: (K,) "ggx" or "beckmann" per lobe (default all GGX).
    """

    diffuse: np.ndarray
    colors: np.ndarray
    grazing: np.ndarray
    alphas: np.ndarray
    sheen: np.ndarray = dataclasses.field(default_factory=lambda: np.zeros(3))
    sheen_sigma: float = 0.5
    distributions: tuple = ()

    def __post_init__(self):
        if not self.distributions:
            object.__setattr__(self, "distributions", ("ggx",) * len(self.alphas))
        for d in self.distributions:
            if d not in DISTRIBUTIONS:
                raise ValueError(f"distribution must be one of {DISTRIBUTIONS}, got {d!r}")
        if len(self.distributions) != len(self.alphas):
            raise ValueError("one distribution per lobe is needed")

    @property
    def roughness(self) -> np.ndarray:
        """(K,) the microfacet nodes' Roughness input, sqrt(alpha)."""
        return np.sqrt(self.alphas)

    def to_dict(self) -> dict:
        """Plain JSON-able dict (floats and lists of floats)."""
        return {
            "model": "lambert+microfacet_schlick+velvet",
            "diffuse": [float(x) for x in self.diffuse],
            "lobes": [
                {"distribution": d, "color": [float(x) for x in c], "grazing": float(b),
                 "alpha": float(a), "roughness": float(np.sqrt(a))}
                for d, c, b, a in zip(self.distributions, self.colors, self.grazing,
                                      self.alphas, strict=True)
            ],
            "sheen": {"color": [float(x) for x in self.sheen], "sigma": float(self.sheen_sigma)},
        }

    @classmethod
    def build(cls, diffuse=(0.0, 0.0, 0.0), lobes=(), sheen=(0.0, 0.0, 0.0),
              sigma: float = 0.5) -> LobeParams:
        """From plain values; lobes: (distribution, (3,) color, grazing, alpha) tuples."""
        return cls(
            diffuse=np.array(diffuse, dtype=np.float64),
            colors=np.array([lobe[1] for lobe in lobes], dtype=np.float64).reshape(-1, 3),
            grazing=np.array([lobe[2] for lobe in lobes], dtype=np.float64),
            alphas=np.array([lobe[3] for lobe in lobes], dtype=np.float64),
            sheen=np.array(sheen, dtype=np.float64),
            sheen_sigma=sigma,
            distributions=tuple(lobe[0] for lobe in lobes),
        )

    @classmethod
    def from_dict(cls, d: dict) -> LobeParams:
        """Inverse of :meth:`to_dict`. Optional: ``grazing`` (0), ``distribution``
        ("ggx"), ``sheen`` (none); a lobe may give ``roughness`` instead of ``alpha``."""
        lobes = d.get("lobes", [])
        alphas = [lobe["alpha"] if "alpha" in lobe else lobe["roughness"] ** 2 for lobe in lobes]
        sheen = d.get("sheen") or {"color": [0.0, 0.0, 0.0], "sigma": 0.5}
        return cls(
            diffuse=np.asarray(d["diffuse"], dtype=np.float64).reshape(3),
            colors=np.asarray([lobe["color"] for lobe in lobes], dtype=np.float64).reshape(-1, 3),
            grazing=np.asarray([lobe.get("grazing", 0.0) for lobe in lobes], dtype=np.float64),
            alphas=np.asarray(alphas, dtype=np.float64).reshape(-1),
            sheen=np.asarray(sheen["color"], dtype=np.float64).reshape(3),
            sheen_sigma=float(sheen["sigma"]),
            distributions=tuple(str(lobe.get("distribution", "ggx")) for lobe in lobes),
        )




# ------------------------------------------------------------------------- evaluation
def _norm_rows(a):
    """``np.linalg.norm(a, axis=1)`` of (N, 3) rows, rounded as it rounds them,
    ``sqrt((a0^2 + a1^2) + a2^2)`` (tested), without its slow reduction over rows of 3."""
    a0, a1, a2 = a[:, 0], a[:, 1], a[:, 2]
    return np.sqrt((a0 * a0 + a1 * a1) + a2 * a2)


def _dot_rows(a, b):
    """``np.einsum("ij,ij->i", a, b)`` of (N, 3) rows, rounded as it rounds them,
    ``(a0 b0 + a2 b2) + a1 b1`` (tested; as ``merl._dot_einsum``)."""
    return (a[:, 0] * b[:, 0] + a[:, 2] * b[:, 2]) + a[:, 1] * b[:, 1]


class Geometry:
    """Cosines of local-frame direction pairs (N,) above the horizon."""

    def __init__(self, l, v):
        self.cos_l = np.ascontiguousarray(l[:, 2])
        self.cos_v = np.ascontiguousarray(v[:, 2])
        h = l + v
        norm = _norm_rows(h)
        ok = norm > 0.0
        self.cos_h = np.clip(np.divide(h[:, 2], norm, out=np.ones_like(norm), where=ok), 0.0, 1.0)
        self.cos_d = np.clip(np.divide(_dot_rows(l, h), norm,
                                       out=np.zeros_like(norm), where=ok), 0.0, 1.0)
        self.schlick = (1.0 - self.cos_d) ** 5

    # The parts of the lobes that do not depend on their width, computed once per
    # Geometry (the fit evaluates dozens of widths on the same cells); each is the
    # very expression the lobe formulas used inline, so no value changes.
    @functools.cached_property
    def _ggx_parts(self):
        c2 = np.minimum(self.cos_h * self.cos_h, 1.0)
        cl, cv = self.cos_l, self.cos_v
        return c2, 1.0 - c2, cl * cl, 1.0 - cl * cl, cv * cv, 1.0 - cv * cv

    @functools.cached_property
    def _beckmann_parts(self):
        c2 = np.clip(self.cos_h * self.cos_h, 1e-300, 1.0)
        tan2 = (1.0 - c2) / c2
        tan2_lv = [np.maximum(1.0 / (cos * cos) - 1.0, 0.0) for cos in (self.cos_l, self.cos_v)]
        return c2, tan2, -tan2, 2.0 * tan2, tan2_lv, 4.0 * self.cos_l * self.cos_v

    def ggx(self, alpha):
        """D G2 / (4 cos_l cos_v) of a GGX lobe of width alpha."""
        a2 = alpha * alpha
        c2, one_minus_c2, cl2, s_l, cv2, s_v = self._ggx_parts
        t = one_minus_c2 + a2 * c2
        d = a2 * INV_PI / (t * t)
        # 4 cos_l cos_v (1 + Lambda_l + Lambda_v) = 2 (cos_v mu_l + cos_l mu_v) with
        # mu = cos sqrt(1 + a^2 tan^2) = sqrt(cos^2 + a^2 sin^2): no division by a cosine.
        cl, cv = self.cos_l, self.cos_v
        mu_l = np.sqrt(cl2 + a2 * s_l)
        mu_v = np.sqrt(cv2 + a2 * s_v)
        return d * 0.5 / (cv * mu_l + cl * mu_v)

    def ggx_dlog(self, alpha):
        """d ggx(alpha) / d ln(alpha)."""
        a2 = alpha * alpha
        c2, one_minus_c2, cl2, s_l, cv2, s_v = self._ggx_parts
        t = one_minus_c2 + a2 * c2
        cl, cv = self.cos_l, self.cos_v
        mu_l = np.sqrt(cl2 + a2 * s_l)
        mu_v = np.sqrt(cv2 + a2 * s_v)
        den = cv * mu_l + cl * mu_v
        shape = a2 * INV_PI / (t * t) * 0.5 / den
        dlog_d = 2.0 - 4.0 * a2 * c2 / t
        dlog_v = -(cv * a2 * s_l / mu_l + cl * a2 * s_v / mu_v) / den
        return shape * (dlog_d + dlog_v)

    def beckmann(self, alpha):
        """D G2 / (4 cos_l cos_v) of a Beckmann lobe of width alpha (Cycles' Lambda)."""
        return self._beckmann(alpha, derivative=False)

    def beckmann_dlog(self, alpha):
        """d beckmann(alpha) / d ln(alpha)."""
        return self._beckmann(alpha, derivative=True)

    def _beckmann(self, alpha, derivative):
        a2 = alpha * alpha
        c2, _tan2, minus_tan2, twice_tan2, tan2_lv, four_cos_lv = self._beckmann_parts
        d = np.exp(minus_tan2 / a2) / (np.pi * a2 * c2 * c2)
        lam, dlam = [], []
        for tan2_cos in tan2_lv:
            t2 = a2 * tan2_cos  # (a tan)^2
            zero = t2 < 0.39  # x = 1 / (a tan) > 1.6: Lambda = 0 (Cycles)
            x = 1.0 / np.sqrt(np.where(zero, 1.0, t2))
            num = (0.396 * x - 1.259) * x + 1.0
            den = (2.181 * x + 3.535) * x
            lam.append(np.where(zero, 0.0, num / den))
            if derivative:  # dx / d ln(alpha) = -x
                dl_dx = ((0.792 * x - 1.259) * den - num * (4.362 * x + 3.535)) / (den * den)
                dlam.append(np.where(zero, 0.0, -x * dl_dx))
        g2 = 1.0 / (1.0 + lam[0] + lam[1])
        shape = d * g2 / four_cos_lv
        if not derivative:
            return shape
        return shape * (twice_tan2 / a2 - 2.0 - (dlam[0] + dlam[1]) * g2)

    def microfacet(self, dist, alpha):
        return self.ggx(alpha) if dist == "ggx" else self.beckmann(alpha)

    def microfacet_dlog(self, dist, alpha):
        return self.ggx_dlog(alpha) if dist == "ggx" else self.beckmann_dlog(alpha)

    def _velvet_parts(self):
        if getattr(self, "_velvet_cache", None) is not None:
            return self._velvet_cache
        ok = (self.cos_h < _VELVET_COS_H_MAX) & (self.cos_d > 1e-5)
        ratio = np.maximum(self.cos_h / np.maximum(self.cos_d, 1e-5), 1e-5)
        g = np.minimum(1.0, 2.0 * ratio * np.minimum(self.cos_l, self.cos_v))
        sin2 = np.where(ok, 1.0 - self.cos_h * self.cos_h, 1.0)
        cot2 = self.cos_h * self.cos_h / sin2
        scale = np.where(ok, g * INV_PI / (sin2 * sin2 * 4.0 * self.cos_l * self.cos_v), 0.0)
        self._velvet_cache = (cot2, scale)  # independent of sigma: computed once
        return self._velvet_cache

    def velvet(self, sigma):
        """D_v G_v / (4 cos_l cos_v) of Cycles' Ashikhmin velvet of roughness sigma."""
        cot2, scale = self._velvet_parts()
        inv = 1.0 / (sigma * sigma)
        return np.exp(-cot2 * inv) * inv * scale

    def velvet_dlog(self, sigma):
        """d velvet(sigma) / d ln(sigma)."""
        cot2, scale = self._velvet_parts()
        inv = 1.0 / (sigma * sigma)
        return np.exp(-cot2 * inv) * inv * scale * (2.0 * cot2 * inv - 2.0)


def _as_params(params) -> LobeParams:
    """A :class:`LobeParams` from itself, its dict, or a fit result holding it
    as ``.params`` (:class:`.fitting.LobeFit`)."""
    if isinstance(params, dict):
        return LobeParams.from_dict(params)
    if isinstance(params, LobeParams):
        return params
    return params.params


def evaluate(params, l: np.ndarray, v: np.ndarray) -> np.ndarray:
    """BRDF of the model, i.e. what Cycles renders, at local-frame direction pairs.

    params: :class:`LobeParams` (or its dict, or a :class:`.fitting.LobeFit`).
    l, v: (N, 3) unit light and view directions, local frame (normal +z), any
    float dtype. Returns rho (N, 3) float64 in 1/sr (no cosine), 0 where
    ``l_z <= 0`` or ``v_z <= 0``. Evaluated in blocks of rows (every row is
    computed on its own, so the blocks change no value): the temporaries stay
    in the cache, which makes a table's million cells about twice as fast.
    """
    p = _as_params(params)
    l = np.asarray(l, dtype=np.float64).reshape(-1, 3)
    v = np.asarray(v, dtype=np.float64).reshape(-1, 3)
    if l.shape != v.shape:
        raise ValueError(f"l and v must have the same shape, got {l.shape} and {v.shape}")
    out = np.zeros((len(l), 3))
    for start in range(0, len(l), _BLOCK):
        block = slice(start, start + _BLOCK)
        out[block] = _evaluate_block(p, l[block], v[block]).T
    return out


def _evaluate_block(p: LobeParams, l: np.ndarray, v: np.ndarray) -> np.ndarray:
    """:func:`evaluate` on one block of rows, channel-major: (3, N), so the sums over
    the lobes run along contiguous rows (the same terms, added in the same order)."""
    above = (l[:, 2] > 0.0) & (v[:, 2] > 0.0)
    out = np.zeros((3, len(l)))
    if not above.any():
        return out
    every = bool(above.all())
    g = Geometry(l, v) if every else Geometry(l[above], v[above])
    rho = np.empty((3, len(g.cos_l)))
    rho[:] = (p.diffuse * INV_PI)[:, None]
    for dist, color, grazing, alpha in zip(p.distributions, p.colors, p.grazing, p.alphas,
                                           strict=True):
        alpha = min(float(alpha), 1.0)  # Cycles: alpha = saturate(roughness)^2
        if alpha * alpha <= _SINGULAR_ALPHA2:  # Cycles treats it as a mirror: no light eval
            continue
        shape = g.microfacet(dist, alpha)
        rise = grazing * g.schlick
        for c in range(3):  # rho += shape (A_k + B_k (1 - l.h)^5), per channel
            rho[c] += shape * (color[c] + rise)
    if np.any(p.sheen != 0.0):
        velvet = g.velvet(float(np.clip(p.sheen_sigma, 0.01, 1.0)))
        for c in range(3):
            rho[c] += velvet * p.sheen[c]
    if every:
        return rho
    out[:, above] = rho
    return out


def tabulate(params) -> np.ndarray:
    """The model on the MERL grid: (3, 90, 90, 180) float64 at the cell centres,
    NaN below the horizon (like :func:`database.make_table`)."""
    p = _as_params(params)
    wi, wo = merl.cell_directions()
    valid = merl.valid_cells()
    table = np.full((3, merl.N_CELLS), np.nan)
    for start in range(0, merl.N_CELLS, _BLOCK):  # blocks of the grid: no (N, 3) copies
        block = slice(start, start + _BLOCK)
        keep = valid[block]
        table[:, block][:, keep] = _evaluate_block(p, wi[block][keep], wo[block][keep])
    return table.reshape(3, *merl.SHAPE)
