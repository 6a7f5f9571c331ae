"""Irradiance ratio between photos from a Lambertian reference (grey card or marked region).

Photos under different lights (or the sun at different times) may receive
different irradiance E. A Lambertian reference seen in every photo measures
it: its linear radiance is L = (albedo / pi) E cos(theta), cos(theta) = n . l,
so per channel the least-squares slope a = sum(L cos) / sum(cos^2) is
proportional to E and E_i / E_ref = a_i / a_ref (the unknown albedo cancels).

Divide photo i's linear radiance by ratios[i] (per channel) to bring it to the
reference photo's irradiance. Radiance should already be on one exposure
scale (core.capture.exif.exposure_scales).

A pixel is used when its cosine is finite and > MIN_COSINE (grazing pixels
are dominated by normal errors), all its channels are finite, and it is not
marked saturated.
"""

from __future__ import annotations

import dataclasses

import numpy as np

MIN_COSINE = 0.1


@dataclasses.dataclass(frozen=True)
class Reference:
    """The reference pixels of one photo.

    radiance: (M, 3) linear RGB radiance of the reference pixels (any float dtype).
    cosine: (M,) n . l of each pixel for this photo's light, or a scalar for all
        (a grey card: 1 when it faces the light).
    saturated: optional (M,) or (M, 3) bool, True where a pixel (or channel)
        clipped; such pixels are left out.
    kind: how the notes name it ("reference region", "grey card").
    """

    radiance: np.ndarray
    cosine: np.ndarray | float = 1.0
    saturated: np.ndarray | None = None
    kind: str = "reference region"


def grey_card(radiance, cosine: float = 1.0, saturated=None) -> Reference:
    """A `Reference` for a grey card: (M, 3) or (3,) radiance, one cosine (default 1)."""
    return Reference(np.atleast_2d(np.asarray(radiance)), float(cosine), saturated, "gray card")


def _slopes(ref: Reference, name: str) -> tuple[np.ndarray, int, int]:
    """Per-channel least-squares slope (3,) of L against cos, pixels used and pixels given."""
    L = np.asarray(ref.radiance, dtype=np.float64)
    if L.ndim == 1 and L.shape == (3,):
        L = L[None, :]
    if L.ndim != 2 or L.shape[1] != 3:
        raise ValueError(f"the reference radiance of {name} must have shape (M, 3), got {L.shape}")
    m = L.shape[0]
    cos = np.asarray(ref.cosine, dtype=np.float64)
    if cos.ndim == 0:
        cos = np.full(m, float(cos))
    if cos.shape != (m,):
        raise ValueError(
            f"the reference cosines of {name} must be a number or have shape ({m},), "
            f"got {cos.shape}"
        )
    keep = np.isfinite(cos) & (cos > MIN_COSINE) & np.all(np.isfinite(L), axis=1)
    if ref.saturated is not None:
        sat = np.asarray(ref.saturated, dtype=bool)
        if sat.shape == (m, 3):
            sat = sat.any(axis=1)
        if sat.shape != (m,):
            raise ValueError(
                f"the saturated mask of {name} must have shape ({m},) or ({m}, 3), got {sat.shape}"
            )
        keep &= ~sat
    used = int(keep.sum())
    if used == 0:
        raise ValueError(
            f"the {ref.kind} of {name} has no usable pixel (all facing away from the light, "
            "non-finite or saturated)"
        )
    c, Lk = cos[keep], L[keep]
    return (c @ Lk) / (c @ c), used, m


def relative_irradiance(references, reference_photo: int = 0, names=None):
    """Irradiance of each photo relative to one photo, per RGB channel.

    references: N entries, a `Reference` or None (no grey card / region in that photo).
    reference_photo: index of the photo whose irradiance is 1.
    names: N photo names for notes and errors (default "photo 1", ...).

    If no photo has a reference, all ratios are 1 and the one note is "no grey
    card or reference region: irradiance assumed equal across photos"; if only
    some have one, ValueError naming the first without.

    Returns (ratios (N, 3) float64: E_i / E_ref per channel, divide photo i's
    radiance by them; notes: one line per photo), e.g. "b.jpg: irradiance
    x(0.512, 0.508, 0.497) of a.jpg from its grey card (400 of 400 pixels)".
    """
    references = list(references)
    n = len(references)
    names = [f"photo {i + 1}" for i in range(n)] if names is None else list(names)
    if len(names) != n:
        raise ValueError(f"names must have one entry per photo ({n}), got {len(names)}")
    index = reference_photo
    if isinstance(index, bool) or not isinstance(index, int | np.integer) or not 0 <= index < n:
        raise ValueError(
            f"reference_photo must be a photo index in [0, {n}), got {reference_photo!r}"
        )
    for i, r in enumerate(references):
        if r is not None and not isinstance(r, Reference):
            raise ValueError(f"references[{i}] must be a Reference or None, got {type(r).__name__}")
    if all(r is None for r in references):
        return (np.ones((n, 3)),
                ["no gray card or reference region: irradiance assumed equal across photos"])
    missing = [i for i, r in enumerate(references) if r is None]
    if missing:
        raise ValueError(
            f"{names[missing[0]]} has no gray card or reference region while other photos do; "
            "mark one in it or remove the others"
        )
    fits = [_slopes(r, names[i]) for i, r in enumerate(references)]
    a_ref = fits[reference_photo][0]
    if not np.all(a_ref > 0.0):
        raise ValueError(
            f"the {references[reference_photo].kind} of {names[reference_photo]} is black in some "
            "channel, so it cannot be the irradiance reference"
        )
    ratios = np.stack([f[0] for f in fits]) / a_ref
    notes = []
    for i, (_, used, given) in enumerate(fits):
        values = ", ".join(f"{v:.3g}" for v in ratios[i])
        what = "reference" if i == reference_photo else f"x({values}) of {names[reference_photo]}"
        notes.append(
            f"{names[i]}: irradiance {what} from its {references[i].kind} "
            f"({used} of {given} pixels)"
        )
    return ratios, notes
