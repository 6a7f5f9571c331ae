"""Fresnel reflectance of smooth interfaces, and RGB optical constants of metals.

All functions are pure numpy and broadcast their arguments against each other
in the usual numpy way: pass ``cos_i[:, None]`` with a per-channel ``(3,)``
index to get an ``(N, 3)`` result.

Conventions
-----------
- ``cos_i`` is the cosine of the angle between the incident direction and the
  interface normal, on the side the light arrives from (dimensionless, in
  [-1, 1]). For the microfacet models in :mod:`models` this is ``wi . h``.
- ``eta`` is the relative index of refraction, transmitted side over incident
  side (``n_t / n_i``). For a dielectric in air that is just its index.
- Reflectance is unpolarised: the mean of the s- and p-polarised power
  reflectances. It is dimensionless, in [0, 1].
"""

from __future__ import annotations

import numpy as np

# Approximate RGB reductions of tabulated optical constants (complex index
# n + i k against air), sampled at roughly 650 / 550 / 450 nm for R / G / B
# from standard compilations (Johnson & Christy 1972 for the noble metals,
# Rakic 1995 for Al, Palik's handbook for the transition metals). A spectral
# renderer would integrate against colour-matching functions instead; for
# building a training set of plausible metal colours three samples suffice.
# name -> ((n_R, n_G, n_B), (k_R, k_G, k_B))
METALS: dict[str, tuple[tuple[float, float, float], tuple[float, float, float]]] = {
    "Ag": ((0.14, 0.12, 0.13), (4.15, 3.35, 2.55)),
    "Al": ((1.49, 0.96, 0.62), (7.82, 6.69, 5.47)),
    "Au": ((0.17, 0.43, 1.40), (3.15, 2.45, 1.90)),
    "Cr": ((3.60, 3.20, 2.50), (3.40, 3.30, 3.20)),
    "Cu": ((0.23, 1.00, 1.20), (3.55, 2.60, 2.40)),
    "Fe": ((2.95, 2.90, 2.45), (3.30, 3.05, 2.80)),
    "Ni": ((2.00, 1.80, 1.60), (3.90, 3.50, 3.00)),
    "Pt": ((2.40, 2.10, 1.80), (4.30, 3.70, 3.10)),
    "Ti": ((2.70, 2.50, 2.10), (3.70, 3.40, 2.90)),
}


def fresnel_dielectric(cos_i, eta):
    """Exact unpolarised Fresnel reflectance of a smooth dielectric interface.

    Parameters
    ----------
    cos_i : array_like, float
        Cosine of the incidence angle, in [-1, 1]. A negative value means the
        light arrives from the transmitted side; then ``eta`` is inverted and
        ``|cos_i|`` is used, so the function is valid from both sides.
    eta : array_like, float, > 0
        Relative index ``n_t / n_i``. Broadcast against ``cos_i``.

    Returns
    -------
    ndarray, float64
        Reflectance in [0, 1]. It is exactly 1 under total internal reflection
        (``eta < 1`` and ``sin(theta_i) >= eta``) and at grazing incidence.
    """
    cos_i = np.asarray(cos_i, dtype=np.float64)
    eta = np.asarray(eta, dtype=np.float64)
    eta = np.where(cos_i < 0.0, 1.0 / eta, eta)
    c = np.minimum(np.abs(cos_i), 1.0)
    # Snell: sin_t = sin_i / eta.
    sin2_t = (1.0 - c * c) / (eta * eta)
    tir = sin2_t >= 1.0
    cos_t = np.sqrt(np.maximum(1.0 - sin2_t, 0.0))
    # Both denominators vanish only under TIR, where the result is fixed to 1.
    den_s = np.where(tir, 1.0, c + eta * cos_t)
    den_p = np.where(tir, 1.0, eta * c + cos_t)
    r_s = (c - eta * cos_t) / den_s
    r_p = (eta * c - cos_t) / den_p
    return np.where(tir, 1.0, 0.5 * (r_s * r_s + r_p * r_p))


def fresnel_conductor(cos_i, eta, k):
    """Exact unpolarised Fresnel reflectance of a smooth conductor seen from air.

    The complex relative index is ``eta + i k``. The closed form below is
    Snell's law with a complex index solved for the transmitted wave
    (``a + i b = eta_c * cos_t``), then the s and p amplitude ratios; it
    reduces to :func:`fresnel_dielectric` when ``k = 0`` and to
    ``((eta - 1)^2 + k^2) / ((eta + 1)^2 + k^2)`` at normal incidence.

    Parameters
    ----------
    cos_i : array_like, float
        Cosine of the incidence angle; ``|cos_i|`` is used (the light is always
        on the air side of a metal).
    eta, k : array_like, float, >= 0
        Real and imaginary parts of the complex index, per channel if wanted.
        Broadcast against ``cos_i``.

    Returns
    -------
    ndarray, float64
        Reflectance in [0, 1]; 1 at grazing incidence.
    """
    c = np.minimum(np.abs(np.asarray(cos_i, dtype=np.float64)), 1.0)
    eta = np.asarray(eta, dtype=np.float64)
    k = np.asarray(k, dtype=np.float64)
    c2 = c * c
    s2 = 1.0 - c2
    t0 = eta * eta - k * k - s2
    # a^2 + b^2 = |eta_c^2 - sin^2|, and a = Re(sqrt(eta_c^2 - sin^2)).
    a2b2 = np.sqrt(t0 * t0 + 4.0 * eta * eta * k * k)
    a = np.sqrt(np.maximum(0.5 * (a2b2 + t0), 0.0))
    tiny = 1e-300
    t1 = a2b2 + c2
    t2 = 2.0 * a * c
    r_s = (t1 - t2) / np.maximum(t1 + t2, tiny)
    t3 = c2 * a2b2 + s2 * s2
    t4 = t2 * s2
    r_p = r_s * (t3 - t4) / np.maximum(t3 + t4, tiny)
    return np.clip(0.5 * (r_s + r_p), 0.0, 1.0)


def fresnel_schlick(cos_i, f0):
    """Schlick's approximation ``f0 + (1 - f0) (1 - cos_i)^5``.

    Parameters
    ----------
    cos_i : array_like, float
        Cosine of the incidence angle; ``|cos_i|`` is used.
    f0 : array_like, float, in [0, 1]
        Reflectance at normal incidence, per channel if wanted.

    Returns
    -------
    ndarray, float64
        Reflectance in [0, 1].
    """
    c = np.minimum(np.abs(np.asarray(cos_i, dtype=np.float64)), 1.0)
    f0 = np.asarray(f0, dtype=np.float64)
    m = 1.0 - c
    m2 = m * m
    return f0 + (1.0 - f0) * (m2 * m2 * m)
