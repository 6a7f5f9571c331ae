"""Per-texel albedo under a region's shared BRDF shape (issue 16; the paper's future work).

A textured region is modelled as one shared BRDF whose diffuse part is scaled,
texel by texel, on the scan's UV map:

    rho_i = a_t(i) * D_i + S_i          (per RGB channel, 1/sr)

- ``rho_i``: an observation's BRDF value, ``L / (E n.l)`` (``core.method.observations``);
- ``t(i)``: the texel the observation's surface point maps to (:func:`texel_index`);
- ``D_i``: the shared shape's diffuse part per unit albedo at the observation's
  directions (``1/pi`` for a Lambert diffuse; the whole table, with ``S = 0``,
  where the specular scales with the colour too);
- ``S_i``: the shared shape's part that does not scale (the specular lobes);
- ``a_t``: the albedo of texel t, (3,) per texel.

:func:`estimate` solves for every ``a_t`` at once (each texel is its own
weighted least-squares problem in one unknown per channel, so the solution is
closed-form and vectorised with ``bincount``):

    a_t = (sum_i u_i w_i D_i (rho_i - S_i) + k p_t / s_p^2) / (sum_i u_i w_i D_i^2 + 1 / s_p^2)

- ``w_i = 1 / sigma_i^2`` with ``sigma_i^2 = (noise rho_i)^2 + (specular_uncertainty S_i)^2``,
  scaled by the noise level the residuals show (their median absolute deviation,
  read where the photos' noise sets the variance, so outliers and a misfitting
  shape do not inflate it): relative photo noise, and a
  specular part that a wrong normal moves (a blunted scan puts highlights where
  its normals do not), so highlight pixels say little about the albedo;
- ``u_i``: Huber weights (IRLS; 1.345 robust standard deviations), so a few
  wrong observations (an interreflection, a misplaced highlight) do not pull a texel;
- ``p_t``: the prior, the scan's own texture (linear colour, baked from the
  ambient photos), scaled per channel by ``k`` (the median over the measured
  texels of the data's ratio to it, on a log scale: each texel counts once, so
  the darkest texels, whose data are the most precise under relative noise, do
  not set it where they are wrong: a shadow, a misregistered texel) and
  trusted to ``s_p = prior_sigma * k p_t`` (relative). With one light the photos
  cannot tell a texel's albedo from the shading of a normal the scan has wrong
  (the error is the same in every photo), so the data's trust is not their
  precision alone: :func:`prior_weighting` splits the squared log ratio of data
  to prior over the texels into the prior's error and the data's, which grows
  with each observation's sensitivity to its normal (``sensitivity``), beside
  the data's variance that the photos do show (what each photo's own estimate of
  a texel misses of the others', :func:`_view_variance`); both
  variances then weigh the mix (``prior_sigma`` None, the default; a number fixes
  it). Where no lit photo sees a texel the prior alone gives it; where there is
  neither, the nearest texel that has a value fills it (in the UV image).
  **Where the photos' own texture is not to be had, the scan's is kept**
  (``stats["pattern"] == "scan texture"``, its texels INFERRED, the photos
  setting its scale): where the photos cannot show a texture by themselves, and
  where they show one that the scan's texture neither agrees with nor is
  rejected by (one colour fitting the data's albedo significantly better than
  the texture's pattern, ``prior_agreement``'s ``rejects``: an ambient
  occlusion baked into a plain object's texture, the sky's reflection on a
  near-black material; then one colour, or the photos' texture). One colour
  is surely wrong where the texture varies, and with one light a blunted
  scan's shading error looks like a texture to every test the photos can make
  of their own: on degraded Spot a mirror's data are too far off to show a
  17:1 texture that the scan's texture holds to 1 %. The photos' own texture is
  mixed with the scan's only where it predicts each photo from the other photos
  clearly better than one colour does (:data:`HELD_OUT_MARGIN`) and better than
  the scan's texture does (made from other photos, it is held out of every lit
  one): a texture the other photos refute is that view's error, however well
  the scan's texture agrees with it (degraded Spot's gold: mixed 0.479 off,
  kept 0.011), and where the scan's texture predicts the photos at least as
  well, the photos' adds their error to it (the numpy scene's blunted silver:
  mixed 0.376 off, kept 0.070). That last comparison is made under the shared
  shape of the moment, and where it is near a tie the shape fitted next follows
  the texture chosen, so the region has two settled states
  (``AlbedoSettings.prior_replaces``; ``core.method.textured.run`` settles
  both and keeps the one that predicts the held-out photos better).

**The shared shape, corrected per bin.** Given the observations' MERL cells, the
shape is also corrected by a factor per coarse bin of directions
(:data:`SHAPE_BINS`, 15 x 9 x 6 bins of theta_h, theta_d, phi_d):
``rho_i = m_b(i) (a_t D_i + S_i)``, each ``m_b`` under a prior ``1 +- shape_sigma``
and their weighted mean held at 1 (the albedo keeps its level), fitted in turn
with the albedo. A reconstructed table misses a measured one by a factor that
varies with the directions; without the correction that factor goes into the
texels a photo sees at those directions. The bins are coarse so that each holds
many texels and each texel (seen in several photos) several bins; with one
photo a texel's bins hold it alone and the correction stays at the prior. The
correction is kept only where it predicts each photo's observations from the
other photos' better than the fit without it (:func:`held_out_misfits`): on a
blunted scan the misfit is the normals', which moves with the surface, not with
the directions, and a correction per bin only trades it between bins and texels
(on degraded Spot the albedo's error rose from 0.35 to 0.54 with it, and the
held-out misfit rose too, 0.81 to 0.85).

Each texel is marked in ``AlbedoMap.coverage``: :data:`MEASURED` (its data
alone give it to ``max_relative_error``), :data:`INFERRED` (from the scan's
texture) or :data:`FILLED`.

**Model only what the region needs.** Whether the albedo varies at all is a
one-way analysis of variance over the measured texels: the between-texel
spread of the data-only estimates against the within-texel noise of the
observations (an F test per channel). A region is given one constant albedo
unless some channel both varies significantly (``p < p_level``) and varies by
more than the photos' own relative noise, and, given each observation's photo,
the texture predicts each photo's observations from the other photos' better
than one colour does, by a clear margin (:data:`HELD_OUT_MARGIN`;
:func:`held_out_misfits`: a blunted scan's mirror varies
texel to texel far beyond the noise, but that variation is each view's own
shading error and does not carry over to the next photo); ``AlbedoMap.reason``
says which and why. ``stats["misfit"]`` (:func:`log_misfit`) says how well the
model fits, the same measure for any ``D`` and ``S`` (``core.method.textured``
chooses its model by it).

Frames and units: texels are indices into a ``(height, width)`` image, row 0 at
the top (as image files store it), ``u`` to the right and ``v`` up (Blender's
UV convention). Albedo is in the units of ``D``'s multiplier (dimensionless
for a Lambert ``D = 1/pi``: the diffuse reflectance).
"""

from __future__ import annotations

import dataclasses

import numpy as np
from scipy import ndimage, stats

from ..brdf import merl
from .reconstruct import HUBER_K

FILLED, INFERRED, MEASURED = 0, 1, 2  # AlbedoMap.coverage codes
COVERAGE_NAMES = {FILLED: "filled", INFERRED: "inferred from the scan's texture",
                  MEASURED: "measured"}
_TINY = 1e-30
SHAPE_BINS = (6, 10, 30)  # MERL cells per bin of the shape's correction (theta_h, theta_d,
# phi_d): 15 x 9 x 6 bins, theta_h's finest near the peak (its cells are square-root spaced)


@dataclasses.dataclass(frozen=True)
class AlbedoSettings:
    """noise: the photos' relative noise (1 sigma of rho), a starting scale only: the
    residuals set the level that weights and the homogeneity test use.
    specular_uncertainty: relative 1-sigma error of the shared specular S at an
    observation (a blunted scan's normals move the highlight). prior_sigma: relative
    1-sigma trust in the scan's texture as the albedo (after its per-channel scale),
    or None (the default): weighed against the data by how far each misses the
    other (:func:`prior_weighting`), :data:`PRIOR_SIGMA` where too few texels say.
    max_relative_error: a texel is MEASURED when its data alone give its albedo to
    this relative standard error. p_level: significance of the albedo's variation
    (F test) below which the region is textured. iterations: IRLS rounds.
    shape_sigma: relative 1-sigma prior on the shared shape's correction per bin of
    directions (used when :func:`estimate` is given the observations' cells).
    prior_replaces: the scan's texture, where the photos show one it agrees with,
    is kept in place of theirs when it predicts each photo at least as well as
    their own does from the other photos (False: it is only weighed with theirs).
    Near a tie the comparison hangs on the shared shape it was made under, so
    ``core.method.textured.run`` tries the region both ways where it decided
    (``stats["prior_predicts"]``) and keeps the one whose photos' texture or
    scan's predicts the held-out photos better."""

    noise: float = 0.01
    specular_uncertainty: float = 0.5
    prior_sigma: float | None = None
    max_relative_error: float = 0.5
    p_level: float = 1e-3
    iterations: int = 6
    shape_sigma: float = 1.0
    prior_replaces: bool = True

    def __post_init__(self):
        for name in ("noise", "specular_uncertainty", "prior_sigma", "max_relative_error",
                     "shape_sigma"):
            value = getattr(self, name)
            if name == "prior_sigma" and value is None:
                continue
            if not (np.isfinite(value) and value > 0.0):
                raise ValueError(f"albedo setting {name} must be a positive number, got {value!r}")
        if not (np.isfinite(self.p_level) and 0.0 < self.p_level < 1.0):
            raise ValueError(f"albedo setting p_level must lie in (0, 1), got {self.p_level!r}")
        if int(self.iterations) != self.iterations or self.iterations < 1:
            raise ValueError(
                f"albedo setting iterations must be a whole number >= 1, got {self.iterations!r}"
            )


@dataclasses.dataclass(frozen=True, eq=False)  # arrays: no element-wise ==
class AlbedoMap:
    """Result of :func:`estimate` for one region.

    albedo: (height * width, 3) float64, every texel finite and >= 0 (constant
    where ``constant``). coverage: (height * width,) uint8, MEASURED / INFERRED /
    FILLED. observations: (height * width,) int64, observations per texel.
    reference: (3,) the region's colour: the mean albedo over the measured texels,
    or its one value when ``constant`` (the precision-weighted mean). constant:
    the region got one albedo. reason: one sentence saying why. measured:
    (height * width,) bool, the texels whose data alone give their albedo to
    ``max_relative_error`` (coverage MEASURED, unless the scan's texture was kept
    for the region: then INFERRED), or None. stats: ``pattern`` (where the
    texture's pattern came from: "one colour", "photos", "photos and scan
    texture" or "scan texture"); per
    channel ``F``, ``p``, ``spread`` (the albedo's relative spread beyond its
    estimation noise), ``noise`` (the photos' relative noise as the residuals show
    it); ``prior_scale`` (3,) or None; counts per coverage code; ``misfit``
    (:func:`log_misfit` of the fit) and ``misfit_where`` (over ``estimate``'s
    ``misfit_where`` observations, or None); ``held_out`` (:func:`held_out_misfits`,
    or None without the observations' photos; with the scan's texture's ``prior``
    and ``textured_at_prior`` where the two textures were compared);
    ``prior_predicts`` (whether that comparison, not agreement alone, decided for
    the scan's texture: see ``AlbedoSettings.prior_replaces``);
    ``shape_correction`` (None when not tried, else whether it was ``kept``, the
    held-out misfits ``held_out_with`` and ``held_out_without`` it, ``bins``, and per
    channel the factors' ``range``).
    """

    shape: tuple
    albedo: np.ndarray
    coverage: np.ndarray
    observations: np.ndarray
    reference: np.ndarray
    constant: bool
    reason: str
    stats: dict
    measured: np.ndarray | None = None

    def image(self) -> np.ndarray:
        """(height, width, 3) float32 albedo image, row 0 at the top."""
        return self.albedo.reshape(*self.shape, 3).astype(np.float32)

    def coverage_image(self) -> np.ndarray:
        """(height, width) uint8 image: 255 measured, 128 inferred, 0 filled."""
        levels = np.array([0, 128, 255], dtype=np.uint8)
        return levels[self.coverage].reshape(self.shape)

    def normalised(self, rho, texel, diffuse) -> np.ndarray:
        """(N, 3) the observations brought to the region's reference albedo,
        ``rho + (reference - a_t) D`` (what the shared shape is fitted to);
        observations without a texel (``texel < 0``) are returned as they are."""
        rho = np.asarray(rho, dtype=np.float64)
        texel = np.asarray(texel, dtype=np.int64)
        out = np.array(rho)
        has = texel >= 0
        out[has] += (self.reference - self.albedo[texel[has]]) * np.asarray(diffuse)[has]
        return out


def uniform(shape, reason: str) -> AlbedoMap:
    """One albedo of 1 for every texel, none measured (coverage FILLED): the map of
    a region whose observations constrain no color; ``reason`` says why."""
    height, width = _shape(shape)
    n = height * width
    return AlbedoMap(shape=(height, width), albedo=np.ones((n, 3)),
                     coverage=np.full(n, FILLED, dtype=np.uint8),
                     observations=np.zeros(n, dtype=np.int64), reference=np.ones(3),
                     constant=True, reason=reason, measured=np.zeros(n, dtype=bool),
                     stats={"channels": [], "pattern": "one colour",
                            "texels": {COVERAGE_NAMES[FILLED]: n, COVERAGE_NAMES[INFERRED]: 0,
                                       COVERAGE_NAMES[MEASURED]: 0},
                            "prior_scale": None})


def texel_index(uv, shape) -> np.ndarray:
    """(N,) int64 flat texel index (row * width + column) of UV coordinates.

    uv: (N, 2), u to the right, v up (Blender's convention); values outside
    [0, 1) wrap, as an image texture repeats. shape: (height, width) of the image;
    row 0 is the image's top. Non-finite UVs give -1 (no texel)."""
    height, width = _shape(shape)
    uv = np.asarray(uv, dtype=np.float64)
    if uv.ndim != 2 or uv.shape[1] != 2:
        raise ValueError(f"uv must have shape (N, 2), got {uv.shape}")
    finite = np.isfinite(uv).all(axis=1)
    safe = np.where(finite[:, None], uv, 0.0)
    frac = safe - np.floor(safe)
    col = np.minimum((frac[:, 0] * width).astype(np.int64), width - 1)
    row = np.minimum(((1.0 - frac[:, 1]) * height).astype(np.int64), height - 1)
    return np.where(finite, row * width + col, -1)


def texel_centres(shape) -> np.ndarray:
    """(height * width, 2) UV of each texel's centre, in :func:`texel_index`'s order."""
    height, width = _shape(shape)
    row, col = np.divmod(np.arange(height * width), width)
    return np.stack([(col + 0.5) / width, 1.0 - (row + 0.5) / height], axis=1)


def shape_bins(cells) -> tuple[np.ndarray, int]:
    """Each observation's coarse bin of directions for the shape's correction:
    (bins (N,) int64 in [0, n_bins), n_bins), the bins numbered over those present.
    cells: (N, 3) MERL cells (theta_h, theta_d, phi_d indices); a bin is
    :data:`SHAPE_BINS` cells on each axis."""
    cells = np.asarray(cells, dtype=np.int64)
    step = np.asarray(SHAPE_BINS)
    counts = -(-np.asarray(merl.SHAPE) // step)  # bins per axis, rounded up
    key = np.ravel_multi_index(tuple((cells // step).T), tuple(counts))
    used, bins = np.unique(key, return_inverse=True)
    return bins.reshape(-1), len(used)


def _shape(shape) -> tuple:
    try:
        height, width = (int(s) for s in shape)
    except (TypeError, ValueError):
        raise ValueError(f"texture shape must be (height, width), got {shape!r}") from None
    if height < 1 or width < 1:
        raise ValueError(f"texture shape must be at least 1 x 1, got {height} x {width}")
    return height, width


def _rows(name: str, a, n: int) -> np.ndarray:
    a = np.asarray(a, dtype=np.float64)
    if a.shape != (n, 3):
        raise ValueError(f"{name} must have shape ({n}, 3), got {a.shape}")
    if not np.isfinite(a).all():
        raise ValueError(f"{name} holds NaN or Inf")
    return a


def estimate(texel, rho, diffuse, specular, shape, *, prior=None, cells=None, views=None,
             sensitivity=None, misfit_where=None,
             settings: AlbedoSettings | None = None) -> AlbedoMap:
    """The per-texel albedo of one region (see the module docstring).

    texel: (N,) int, each observation's flat texel (:func:`texel_index`; -1 for
    none). rho: (N, 3) observed BRDF values (1/sr). diffuse: (N, 3) the shared
    diffuse part per unit albedo at each observation (1/sr, >= 0). specular:
    (N, 3) the shared part that does not scale (1/sr). shape: (height, width) of
    the albedo image. prior: (height * width, 3) or (height, width, 3) linear
    colour of the scan's texture (NaN where it has none), or None. cells: (N, 3)
    the observations' MERL cells (``Samples.cells``), or None: with them the shared
    shape is corrected per coarse bin of directions (:data:`SHAPE_BINS`) while the
    albedo is fitted, where that predicts the photos better (it needs ``views``;
    see the module docstring). views: (N,) int, the photo each
    observation comes from, or None: with them a texture must also predict each
    photo's observations from the other photos better than one colour does
    (:func:`held_out_misfits`). sensitivity: (N,) >= 0, how far each observation
    moves, relative, per radian its normal turns (the caller's model: the light's
    slant and the table's slope, ``core.method.textured.normal_sensitivity``), or
    None: with it and a prior the data's error grows with it where the scan's
    normals are off (:func:`prior_weighting`). misfit_where: (N,) bool or None:
    the observations over which ``stats["misfit_where"]`` is also given (the
    same :func:`log_misfit`; None when no observation of it has a texel).

    ValueError (one sentence) for shapes that do not match, NaN or Inf in the
    observations, negative diffuse, or when no observation constrains any texel.
    """
    settings = settings or AlbedoSettings()
    height, width = _shape(shape)
    n_texels = height * width
    texel = np.asarray(texel)
    if texel.ndim != 1 or not np.issubdtype(texel.dtype, np.integer):
        raise ValueError(f"texel must be a 1-D integer array, got {texel.dtype} {texel.shape}")
    n = len(texel)
    rho = _rows("rho", rho, n)
    diffuse = _rows("diffuse", diffuse, n)
    specular = _rows("specular", specular, n)
    if (diffuse < 0.0).any():
        raise ValueError("diffuse must not be negative")
    if (texel >= n_texels).any():
        raise ValueError(f"texel indices must be below {n_texels} (the {height} x {width} image)")
    if prior is not None:
        prior = np.asarray(prior, dtype=np.float64).reshape(-1, 3) if np.ndim(prior) == 3 \
            else np.asarray(prior, dtype=np.float64)
        if prior.shape != (n_texels, 3):
            raise ValueError(f"prior must have shape ({n_texels}, 3) or ({height}, {width}, 3), "
                             f"got {prior.shape}")
        if np.isinf(prior).any() or (prior < 0.0).any():
            raise ValueError("the prior texture holds Inf or negative values")

    if cells is not None:
        cells = np.asarray(cells)
        if cells.shape != (n, 3) or not np.issubdtype(cells.dtype, np.integer):
            raise ValueError(f"cells must be an integer array of shape ({n}, 3), "
                             f"got {cells.dtype} {cells.shape}")
    if views is not None:
        views = np.asarray(views)
        if views.shape != (n,) or not np.issubdtype(views.dtype, np.integer) or (
                n and views.min() < 0):
            raise ValueError(f"views must be {n} photo indices >= 0, got {views.dtype} "
                             f"{views.shape}")
    if sensitivity is not None:
        sensitivity = np.asarray(sensitivity, dtype=np.float64)
        if sensitivity.shape != (n,) or not np.isfinite(sensitivity).all() or (
                sensitivity < 0.0).any():
            raise ValueError(f"sensitivity must be {n} finite values >= 0, "
                             f"got {sensitivity.shape}")
    if misfit_where is not None:
        misfit_where = np.asarray(misfit_where)
        if misfit_where.shape != (n,) or misfit_where.dtype != bool:
            raise ValueError(f"misfit_where must be {n} booleans, got {misfit_where.dtype} "
                             f"{misfit_where.shape}")
    keep = texel >= 0
    texel, rho, diffuse, specular = texel[keep], rho[keep], diffuse[keep], specular[keep]
    where = None if misfit_where is None else misfit_where[keep]
    bins, n_bins = (None, 0) if cells is None else shape_bins(cells[keep])
    count = np.bincount(texel, minlength=n_texels)
    # the fits run over the texels that have observations only (a 4k texture has
    # 16 M texels, a region's photos see a few hundred thousand), then are scattered
    used, local = np.unique(texel, return_inverse=True)
    views = None if views is None else views[keep]

    def fitted(bins, n_bins):
        return [_channel(local, rho[:, c], diffuse[:, c], specular[:, c], len(used), settings,
                         bins, n_bins) for c in range(3)]

    fits = fitted(None, 0)
    predictions = None if views is None else held_out_predictions(
        local, views, rho, diffuse, specular, fits, len(used), settings=settings)
    held_out = None if predictions is None else held_out_misfits(rho, predictions)
    correction = None
    if bins is not None and held_out is not None and held_out["observations"] >= _MIN_HELD_OUT:
        # the correction is kept where it predicts each photo from the others better
        corrected = fitted(bins, n_bins)
        corrected_predictions = held_out_predictions(
            local, views, rho, diffuse, specular, corrected, len(used), bins, n_bins, settings)
        with_it = held_out_misfits(rho, corrected_predictions)
        correction = {"kept": with_it["textured"] < held_out["textured"],
                      "held_out_with": with_it["textured"],
                      "held_out_without": held_out["textured"], "bins": int(n_bins)}
        if correction["kept"]:
            fits, held_out, predictions = corrected, with_it, corrected_predictions
    a = np.zeros((n_texels, 3))  # data-only estimates
    h = np.zeros((n_texels, 3))  # their precisions (0: no data)
    a[used] = np.stack([f["a"] for f in fits], axis=1)
    h[used] = np.stack([f["h"] for f in fits], axis=1)
    # measured: the grey level (the channels' mean) known to max_relative_error
    constrained = (h > _TINY).all(axis=1)
    grey = a.mean(axis=1)
    grey_se = np.sqrt(np.sum(1.0 / np.maximum(h, _TINY), axis=1)) / 3.0
    measured = constrained & (grey_se <= settings.max_relative_error * np.abs(grey))
    if not measured.any():
        raise ValueError("no observation constrains this region's albedo "
                         "(no lit photo sees its texture, or its diffuse part is zero)")
    weighted = np.sum(h[measured] * a[measured], axis=0) / np.sum(h[measured], axis=0)
    if not (weighted > 0.0).all():  # the model explains the light without any colour
        raise ValueError("no observation constrains this region's albedo (under this "
                         "model its colour comes out zero or negative)")
    predicted = np.stack([f["mi"] for f in fits], axis=1) * (a[texel] * diffuse + specular)
    channel_stats = [_variation(a[measured, c], h[measured, c], weighted[c], fits[c]["dof"],
                                fits[c]["noise"], settings) for c in range(3)]
    textured = [s["p"] < settings.p_level and s["spread"] > s["noise"] for s in channel_stats]
    predicts = held_out is None or held_out["observations"] < _MIN_HELD_OUT or (
        held_out["textured"] < HELD_OUT_MARGIN * held_out["constant"])
    k = None if prior is None else _prior_scale(a, measured, prior)
    agreement = None if prior is None else prior_agreement(a, measured, prior, k,
                                                           settings.p_level)
    constant = not (any(textured) and predicts)
    scan_predicts = False
    if agreement is not None and not constant and held_out is not None \
            and held_out["observations"] >= _MIN_HELD_OUT:
        # the scan's texture, made from other photos, predicts each photo as the
        # photos' own texture does, from the others: it is the better of the two
        # where it predicts them at least as well (a blunted scan's metal, whose
        # photos' texture is its shading error)
        held_out = held_out_misfits(rho, predictions, diffuse, specular, local,
                                    (k * prior)[used])
        scan_predicts = held_out["prior_observations"] >= _MIN_HELD_OUT and (
            held_out["prior"] <= held_out["textured_at_prior"])
    # the comparison decides only where the photos show a texture the scan's agrees with
    prior_predicts = bool(scan_predicts and not constant and not agreement["rejects"]
                          and agreement["agrees"])
    scan_predicts = scan_predicts and settings.prior_replaces
    # the scan's texture is kept unless one colour fits the data significantly better
    # (then one colour, or the data's own texture) where the photos cannot show a
    # texture, where they show one the scan's texture neither agrees with nor
    # rejects (a blunted mirror's texture, which is its shading error: the user's
    # texture is the better bet, and one colour is surely wrong where it varies),
    # and where it predicts the photos at least as well as theirs
    kept = bool(agreement is not None and not agreement["rejects"] and (
        constant or not agreement["agrees"] or scan_predicts))
    constant = constant and not kept
    # the region's colour: its one value (the estimate of least variance), or the
    # mean over the measured texels (each texel as much surface as another)
    reference = weighted if constant else a[measured].mean(axis=0)

    albedo = np.where(measured[:, None], a, np.nan)
    weighting = None
    if kept:
        has = np.isfinite(prior).all(axis=1)
        albedo = np.where(has[:, None], k * np.where(has[:, None], prior, 0.0), np.nan)
        reference = albedo[measured & has].mean(axis=0)
    elif prior is not None:
        slant, view_var = None, None
        if sensitivity is not None:
            # each texel's sensitivity, squared: the mean over its observations with
            # the fit's weights (one normal error moves them all, and the estimate
            # heeds each as much as its weight; a highlight's flank, weighted down,
            # does not make the texel's estimate sensitive)
            weight = np.mean([f["weight"] for f in fits], axis=0)
            wg = np.bincount(local, weight * sensitivity[keep], minlength=len(used))
            wsum = np.bincount(local, weight, minlength=len(used))
            slant = np.zeros(n_texels)
            slant[used] = (wg / np.maximum(wsum, _TINY)) ** 2
        if views is not None:
            view_var = _view_variance(local, views, rho, diffuse, specular, fits, used,
                                      n_texels)
        albedo, weighting = _with_prior(a, h, measured, prior, k, reference, settings, slant,
                                        view_var)

    coverage = np.full(n_texels, FILLED, dtype=np.uint8)
    if prior is not None and not constant:  # a constant region takes nothing from it
        coverage[np.isfinite(prior).all(axis=1) & np.isfinite(albedo).all(axis=1)] = INFERRED
    if not kept:  # kept: every value is the scan's texture's, the photos set its scale
        coverage[measured] = MEASURED
    if constant:
        albedo = np.broadcast_to(reference, (n_texels, 3)).copy()
    else:
        albedo = _fill(albedo, coverage != FILLED, (height, width), reference)
    albedo = np.maximum(albedo, 0.0)
    if correction is not None:
        correction["range"] = [[float(f["m"].min()), float(f["m"].max())] for f in fits]
    reason = _reason(constant, channel_stats, settings, held_out, agreement if kept else None)
    pattern = ("one colour" if constant else "scan texture" if kept
               else "photos" if prior is None else "photos and scan texture")
    counts = {COVERAGE_NAMES[code]: int(np.sum(coverage == code)) for code in COVERAGE_NAMES}
    return AlbedoMap(
        shape=(height, width), albedo=albedo, coverage=coverage, observations=count,
        reference=reference, constant=constant, reason=reason, measured=measured,
        stats={"channels": channel_stats, "texels": counts, "pattern": pattern,
               "misfit": log_misfit(rho, predicted),
               "misfit_where": None if where is None or not where.any()
               else log_misfit(rho[where], predicted[where]), "held_out": held_out,
               "shape_correction": correction,
               "prior_scale": None if k is None else k.tolist(),
               "prior_weighting": weighting, "prior_agreement": agreement,
               "prior_predicts": prior_predicts},
    )


_MIN_NOISE_DOF = 30  # fewer residual degrees of freedom: the assumed noise is used
_ALTERNATIONS = 20  # most albedo <-> shape-correction turns per IRLS round
_SETTLED = 1e-4  # ... fewer once no bin's correction moves by this (relative)


def _channel(texel, rho, d, s, n_texels, settings: AlbedoSettings, bins=None, n_bins=0):
    """One channel's IRLS. Returns a dict of:

    - a (T,): the data-only albedo (0 where no data); h (T,): its precision (1 /
      variance at the noise level the residuals show, 0 where no data);
    - dof: the residuals' degrees of freedom; noise: the relative noise of one
      observation's albedo (the residuals' robust scale times ``noise``, the median
      over the observations whose variance the photos' noise sets);
    - m (n_bins,): the shape's correction per bin (ones without bins); weight (N,):
      each observation's final weight (Huber over the variance at the residuals'
      noise level); mi (N,): the correction at each observation.

    bins: (N,) int in [0, n_bins), each observation's coarse bin of directions, or
    None. With bins the shared shape is corrected per bin, ``rho_i = m_b(i) (a_t D_i
    + S_i)``: inside each IRLS round the albedo and the correction are fitted in turn
    until the correction settles (``_ALTERNATIONS`` at most)."""
    target = rho - s
    sigma2 = (settings.noise * rho) ** 2 + (settings.specular_uncertainty * s) ** 2
    sigma2 = np.maximum(sigma2, (settings.noise * 1e-3 * np.max(np.abs(rho), initial=0.0)) ** 2
                        + _TINY)
    w = 1.0 / sigma2
    # the noise's scale is read where the photos' noise, not the specular's
    # uncertainty, sets an observation's variance (all of them where too few do)
    quiet = (settings.noise * rho) ** 2 >= (settings.specular_uncertainty * s) ** 2
    if quiet.sum() < _MIN_NOISE_DOF:
        quiet = np.ones_like(quiet)
    u = np.ones_like(rho)
    m = np.ones(max(int(n_bins), 1))
    mi = np.ones_like(rho)  # the correction at each observation
    s2, dof = 1.0, 0
    n_free = (int(np.sum(np.bincount(bins, minlength=n_bins) > 0)) if bins is not None else 0)

    def albedo(weight, mi):
        dm = mi * d
        hu = np.bincount(texel, weight * dm * dm, minlength=n_texels)
        bu = np.bincount(texel, weight * dm * (rho - mi * s), minlength=n_texels)
        ok = hu > _TINY
        return np.where(ok, bu / np.where(ok, hu, 1.0), 0.0), hu

    for _ in range(int(settings.iterations)):
        a, hu = albedo(u * w, mi)
        for _ in range(_ALTERNATIONS if bins is not None else 0):
            before = m
            m, mi = _shape_correction(bins, n_bins, rho, a[texel] * d + s, u * w / s2,
                                      settings.shape_sigma)
            a, hu = albedo(u * w, mi)
            if np.max(np.abs(m - before) / before) < _SETTLED:
                break
        dm = mi * d
        r = (rho - mi * s - a[texel] * dm) * np.sqrt(w)
        dof = len(r) - int(np.sum(hu > _TINY)) - n_free
        # with few repeated observations the residuals cannot tell the noise: assume it
        s2 = _robust_scale2(r[quiet], (u * w * dm * dm / np.maximum(hu, _TINY)[texel])[quiet]) \
            if dof >= _MIN_NOISE_DOF else 1.0
        z = np.abs(r) / np.sqrt(s2)
        u = np.minimum(1.0, HUBER_K / np.maximum(z, _TINY))
    a, hu = albedo(u * w, mi)  # under the last weights
    h = hu / s2
    level = np.sqrt(s2) * np.sqrt(sigma2) / np.maximum(np.abs(target), _TINY)
    read = quiet & (np.abs(target) > _TINY)
    noise = float(np.median(level[read])) if read.any() else float(
        np.median(level)) if len(level) else settings.noise
    return {"a": a, "h": np.where(hu > _TINY, h, 0.0), "dof": max(dof, 0), "noise": noise,
            "m": m, "weight": u * w / s2, "mi": mi}


_MIN_HELD_OUT = 30  # fewer held-out observations: the texture is judged without them
HELD_OUT_MARGIN = 0.8  # a texture must predict the held-out photos this much better than
# one colour: texture_bench's 76 regions (2026-12-04) fell into ratios below 0.67, where
# the texture beat one colour's error, and 0.83 to 0.89, blunted mirrors and copper whose
# textures were 0.45 to 0.97 off (one colour: 0.37 to 0.43)


@dataclasses.dataclass(frozen=True)
class HeldOut:
    """:func:`held_out_predictions`' result, each (N, 3): by the texel's albedo from
    the other photos (``textured``) and by the region's one colour from them
    (``constant``); the shape's correction each used (``correction``); and (N,)
    ``held``, the observations predicted."""

    textured: np.ndarray
    constant: np.ndarray
    correction: np.ndarray
    held: np.ndarray


def held_out_predictions(texel, views, rho, d, s, fits, n_texels, bins=None, n_bins=0,
                         settings: AlbedoSettings | None = None) -> HeldOut:
    """Leave one photo out: each observation predicted from the other photos'
    observations only, by its texel's albedo and by the region's one colour, both
    with the fits' weights; with ``bins`` the shape's correction of each bin is
    also refitted without the photo (a bin that photo alone sees keeps the prior,
    1). Scored by :func:`held_out_misfits`. texel: (N,) local texel ids in [0,
    n_texels); views: (N,) photo ids; rho, d, s: (N, 3); fits: per channel
    ``_channel``'s result."""
    settings = settings or AlbedoSettings()
    n_views = int(views.max(initial=0)) + 1

    def pairs(key):  # each observation's (key, photo) pair, numbered
        return np.unique(key * n_views + views, return_inverse=True)[1].reshape(-1)

    def others(key, pair, values, size):  # sums over each observation's key, less its photo's
        return (np.bincount(key, values, minlength=size)[key]
                - np.bincount(pair, values)[pair])

    texel_pair = pairs(texel)
    bin_pair = None if bins is None else pairs(bins)

    tex, one, correction = np.zeros_like(rho), np.zeros_like(rho), np.zeros_like(rho)
    # where the colour part is the smaller share, both predictions are the shared
    # part's and the comparison would be decided by noise: those are left out
    held = np.sum(np.stack([f["a"][texel] for f in fits], axis=1) * d, axis=1) >= np.sum(s, axis=1)
    for c, f in enumerate(fits):
        weight, mi = f["weight"], f["mi"]
        if bins is not None:
            p = f["a"][texel] * d[:, c] + s[:, c]
            prior = 1.0 / settings.shape_sigma**2
            level = np.sum(weight * p * p * mi) / max(np.sum(weight * p * p), _TINY)
            mi = (others(bins, bin_pair, weight * p * rho[:, c], n_bins) + prior) / (
                others(bins, bin_pair, weight * p * p, n_bins) + prior) / level
        dm = mi * d[:, c]
        big_w = weight * dm * dm
        big_b = weight * dm * (rho[:, c] - mi * s[:, c])
        w_o = others(texel, texel_pair, big_w, n_texels)
        held &= w_o > 1e-9 * np.bincount(texel, big_w, minlength=n_texels)[texel]
        a_tex = np.where(w_o > 0.0, others(texel, texel_pair, big_b, n_texels) / np.where(
            w_o > 0.0, w_o, 1.0), 0.0)
        w_v, b_v = np.bincount(views, big_w), np.bincount(views, big_b)
        rest = big_w.sum() - w_v[views]
        a_one = np.where(rest > _TINY, (big_b.sum() - b_v[views]) / np.maximum(rest, _TINY),
                         0.0)
        tex[:, c] = mi * (a_tex * d[:, c] + s[:, c])
        one[:, c] = mi * (a_one * d[:, c] + s[:, c])
        correction[:, c] = mi
    return HeldOut(textured=tex, constant=one, correction=correction, held=held)


def held_out_misfits(rho, predictions: HeldOut, d=None, s=None, texel=None,
                     scan_texture=None) -> dict:
    """The leave-one-photo-out test's misfits from :func:`held_out_predictions`:
    {"textured", "constant": :func:`log_misfit` of the two predictions,
    "observations": how many were predicted (those whose texel another photo also
    sees)}. scan_texture: (n_texels, 3) the scan's texture at the local texels,
    scaled (NaN where it has none), or None; given (with the observations' d, s
    and local texel), each observation is also predicted by it (made from other
    photos than the lit ones) and the result adds "prior" and
    "textured_at_prior", the misfits of its prediction and of the photos'
    texture over the observations it covers, and "prior_observations" (how
    many)."""
    held, tex = predictions.held, predictions.textured
    out = {"textured": log_misfit(rho[held], tex[held]),
           "constant": log_misfit(rho[held], predictions.constant[held]),
           "observations": int(held.sum())}
    if scan_texture is not None:
        scan = predictions.correction * (np.nan_to_num(scan_texture[texel]) * d + s)
        covered = held & np.isfinite(scan_texture[texel]).all(axis=1)
        out.update(prior=log_misfit(rho[covered], scan[covered]),
                   textured_at_prior=log_misfit(rho[covered], tex[covered]),
                   prior_observations=int(covered.sum()))
    return out


def log_misfit(rho, predicted) -> float:
    """How far a model's predictions miss the observations, the same measure for
    every model: the robust root-mean-square (Huber, ``HUBER_K`` robust standard
    deviations) of ``log(predicted / rho)`` over the observations and channels
    brighter than 1e-6 of the brightest (the darker ones say nothing in a ratio;
    predictions are floored there too). rho, predicted: (N, 3)."""
    rho = np.asarray(rho, dtype=np.float64).reshape(-1)
    predicted = np.asarray(predicted, dtype=np.float64).reshape(-1)
    if not rho.size:
        return 0.0
    floor = 1e-6 * max(float(np.max(rho)), _TINY)
    lit = rho > floor
    if not lit.any():
        return 0.0
    z = np.abs(np.log(np.maximum(predicted[lit], floor) / rho[lit]))
    scale = 1.4826 * float(np.median(z))
    if scale <= 0.0:  # most predictions exact: the mean square says how far the rest are
        return float(np.sqrt(np.mean(z * z)))
    k = HUBER_K * scale
    return float(np.sqrt(np.mean(np.where(z <= k, z * z, k * (2.0 * z - k)))))


def _robust_scale2(r, leverage) -> float:
    """The residuals' variance from their median absolute deviation (1.4826 MAD, the
    normal's sigma), each residual first divided by sqrt(1 - leverage) (a texel's
    fit takes up part of its own observations' noise), over the observations their
    texel does not fit exactly (leverage below 0.99). r, leverage: (N,)."""
    free = leverage < 0.99
    if not free.any():
        return 1.0
    z = np.abs(r[free]) / np.sqrt(1.0 - leverage[free])
    return max(float((1.4826 * np.median(z)) ** 2), _TINY)


def _shape_correction(bins, n_bins, rho, predicted, weight, sigma):
    """The shared shape's correction per bin, m (n_bins,), and at each observation
    (N,): the weighted least-squares factor of ``rho ~ m_b predicted`` per bin under a
    prior ``m_b ~ 1 +- sigma`` (so a bin without evidence keeps the table as it is),
    then divided by its mean over the observations (weighted as the fit weighs
    them), so the correction moves the shape and the albedo keeps its level.
    weight: (N,) the observations' weights (1 / variance of rho)."""
    prior = 1.0 / sigma**2
    num = np.bincount(bins, weight * predicted * rho, minlength=n_bins) + prior
    den = np.bincount(bins, weight * predicted * predicted, minlength=n_bins) + prior
    m = np.maximum(num / den, 1e-3)  # a bin the data say is black keeps a trace of shape
    at = m[bins]
    share = weight * predicted * predicted
    level = float(np.sum(share * at) / np.sum(share)) if np.sum(share) > _TINY else 1.0
    m = m / level
    return m, m[bins]


def _variation(a, h, reference, dof_within, noise, settings) -> dict:
    """One channel's test of a constant albedo over its measured texels (a, h: their
    data-only estimates and precisions): F = the between-texel chi^2 per degree of
    freedom (1 for a constant albedo), its p-value (F distribution against the
    residuals' degrees of freedom, or chi^2 when the noise was assumed), and the
    relative spread beyond the estimates' own noise, against the photos' noise."""
    m = len(a)
    between = float(np.sum(h * (a - reference) ** 2))
    dof = max(m - 1, 1)
    f_stat = between / dof
    if m < 2:
        p = 1.0
    elif dof_within >= _MIN_NOISE_DOF:
        p = float(stats.f.sf(f_stat, dof, dof_within))
    else:
        p = float(stats.chi2.sf(between, dof))
    weights = h / np.sum(h)
    observed = float(np.sum(weights * (a - reference) ** 2))
    expected = float(np.sum(weights / h))  # the estimates' own variance, weighted alike
    spread = float(np.sqrt(max(observed - expected, 0.0))) / max(abs(reference), _TINY)
    return {"F": f_stat, "p": p, "spread": spread, "noise": noise, "texels": m,
            "noise_from": "residuals" if dof_within >= _MIN_NOISE_DOF else "assumed"}


def _view_variance(texel, views, rho, d, s, fits, used, n_texels) -> np.ndarray | None:
    """(T,) the relative variance of each texel's data-only albedo that comes from
    the photos disagreeing: each photo's own estimate of the texel (the fits'
    weights and shape correction, so highlights count as little as in the fit),
    its squared grey log deviation from the texel's estimate pooled over texels
    that two or more photos see (median, as a chi-square's; times m / (m - 1) for
    a deviation from a mean that holds it), over the m photos that see each texel.
    A highlight a blunted scan misplaces moves with the view, so this is the part
    of the data's error the photos show. texel: (N,) local ids; used: their global
    texels. None when no texel is seen by two photos."""
    n_views = int(views.max(initial=0)) + 1
    pair_id, pair = np.unique(texel * n_views + views, return_inverse=True)
    pair = pair.reshape(-1)
    owner = pair_id // n_views
    logs = []
    for c, f in enumerate(fits):  # three channels
        dm = f["mi"] * d[:, c]
        num = np.bincount(pair, f["weight"] * dm * (rho[:, c] - f["mi"] * s[:, c]),
                          minlength=len(pair_id))
        den = np.bincount(pair, f["weight"] * dm * dm, minlength=len(pair_id))
        a_pair = np.where(den > _TINY, num / np.where(den > _TINY, den, 1.0), np.nan)
        logs.append(np.log(np.where((a_pair > 0.0) & (f["a"][owner] > 0.0),
                                    a_pair / np.where(f["a"][owner] > 0.0, f["a"][owner], 1.0),
                                    np.nan)))
    dev = np.mean(logs, axis=0)
    photos = np.bincount(owner, minlength=len(used))
    m = photos[owner]
    ok = np.isfinite(dev) & (m >= 2)
    if not ok.any():
        return None
    sigma2 = float(np.median(dev[ok] ** 2 * m[ok] / (m[ok] - 1.0))) / _MEDIAN_CHI2_1
    out = np.zeros(n_texels)
    out[used] = sigma2 / np.maximum(photos, 1)
    return out


def _with_prior(a, h, measured, prior, k, reference, settings, slant=None, view_var=None):
    """The albedo (T, 3), given the prior's per-channel scale k (3,)
    (:func:`_prior_scale`): the data and k p_t combined by their relative variances
    (:func:`prior_weighting`) where the prior has a value, the data alone where it
    has not, NaN where neither; and the weighting's record (dict)."""
    has = np.isfinite(prior)
    p = np.where(has, prior, 0.0)
    usable = has & np.isfinite(k)
    kp = np.where(usable, np.nan_to_num(k) * p, 0.0)
    # relative variances, each at the larger of the two levels (so neither the
    # darker data nor the darker prior is the more precise for being dark)
    level = np.maximum(np.maximum(a, kp), 0.01 * np.abs(reference))
    data_var = np.where(measured[:, None] & (h > _TINY), 1.0 / np.maximum(h, _TINY) / level**2,
                        np.inf)
    if view_var is not None:
        data_var = data_var + view_var[:, None]
    weighting = prior_weighting(a, kp, data_var, measured & usable.all(axis=1) & (
        a > 0.0).all(axis=1), slant, settings)
    if slant is not None:
        data_var = data_var + weighting["normal_sigma"] ** 2 * slant[:, None]
    data_w = np.where(np.isfinite(data_var), 1.0 / np.maximum(data_var, _TINY), 0.0)
    prior_w = np.where(usable, 1.0 / weighting["prior_sigma"] ** 2, 0.0)
    total = data_w + prior_w
    mix = data_w * np.where(measured[:, None], a, 0.0) + prior_w * kp
    out = np.where(total > 0.0, mix / np.where(total > 0.0, total, 1.0), np.nan)
    return out, weighting


def _prior_scale(a, measured, prior) -> np.ndarray:
    """(3,) k per channel: the median of log(a / p) over measured texels with both
    positive, each texel once (NaN where there is none)."""
    has = np.isfinite(prior)
    p = np.where(has, prior, 0.0)
    k = np.full(3, np.nan)
    for c in range(3):
        both = measured & has[:, c] & (p[:, c] > 0.0) & (a[:, c] > 0.0)
        if both.any():  # each texel once, on a log scale (see the module docstring)
            k[c] = np.exp(np.median(np.log(a[both, c] / p[both, c])))
    return k


def prior_agreement(a, measured, prior, k, p_level: float) -> dict | None:
    """Whether the scan's texture predicts the data's albedo (a (T, 3), data only)
    better than one colour does: per measured texel, the squared grey log ratio
    of the data to the scaled prior against the same to one colour (the data's
    geometric mean); they agree where the first is the smaller, one-sided
    Wilcoxon signed-rank p below ``p_level``. The prior was made from other photos
    than the lit ones, so a pattern both show is the surface's, however noisy the
    data are; a prior whose pattern is not in the data (an ambient occlusion
    baked into a plain object's texture) only adds to the ratios, and one colour
    predicting the data better (the other one-sided test, ``p_one_colour``)
    ``rejects`` the texture's pattern; neither agreeing nor rejected, the scan's
    texture is kept (:func:`estimate`). k:
    (3,) the prior's scale (:func:`_prior_scale`). None when fewer than
    :data:`_MIN_WEIGHING` texels have both."""
    has = np.isfinite(prior)
    p = np.where(has, prior, 0.0)
    both = measured & has.all(axis=1) & (p > 0.0).all(axis=1) & (a > 0.0).all(axis=1)
    if not np.isfinite(k).all() or both.sum() < _MIN_WEIGHING:
        return None
    la = np.log(a[both])
    to_prior = np.mean(la - np.log(k * p[both]), axis=1) ** 2
    to_one = np.mean(la - np.median(la, axis=0), axis=1) ** 2
    p_value = float(stats.wilcoxon(to_one - to_prior, alternative="greater").pvalue)
    p_reject = float(stats.wilcoxon(to_one - to_prior, alternative="less").pvalue)
    return {"to_prior": float(np.median(to_prior)), "to_one": float(np.median(to_one)),
            "p": p_value, "agrees": bool(p_value < p_level),
            "p_one_colour": p_reject, "rejects": bool(p_reject < p_level),
            "texels": int(both.sum())}


PRIOR_SIGMA = 0.25  # the prior's relative error where the data cannot say
_MIN_WEIGHING = 64  # fewer texels with both: PRIOR_SIGMA and the data's own precision
_WEIGHING_BINS = 8  # bins of the light's slant over which the two variances are read
_MEDIAN_CHI2_1 = 0.4549  # the median of a chi-square with one degree of freedom


def prior_weighting(a, kp, data_var, both, slant, settings: AlbedoSettings) -> dict:
    """How far to trust the scan's texture against the lit photos' data.

    a, kp: (T, 3) the data-only albedo and the scaled prior; data_var: (T, 3) the
    data's relative variance from its residuals and, where the photos say, from
    how far each photo's own estimate of the texel misses the others'
    (:func:`_view_variance`: a highlight a blunted scan misplaces moves with the
    view); both: (T,) bool texels where both are usable; slant: (T,) each texel's
    sensitivity to its normal squared (g^2: the mean of :func:`estimate`'s
    ``sensitivity`` over its observations with the fit's weights), or None. With
    one light the photos cannot tell an albedo from the shading of a wrong normal
    (the same error is in every photo), so that error is read against the prior:
    over the texels, the squared log ratio of the data to the prior is modelled as

        r_t^2 = prior_sigma^2 + normal_sigma^2 g_t^2 + data_var_t

    (a normal wrong by an angle e moves an observation by about g e relative; the
    prior's error does not depend on the light), fitted by non-negative least
    squares to the medians of r^2 in :data:`_WEIGHING_BINS` bins of g^2 (robust: a
    misregistered texel or an edge is one large r^2 among many); the intercept is
    the prior's (at least ``settings.noise``).
    ``settings.prior_sigma``, when set, is used as given (and normal_sigma is 0).

    Returns {"prior_sigma", "normal_sigma" (radians), "from": "setting", "data",
    "too few texels" or "no sensitivity" (PRIOR_SIGMA), "texels"}."""
    from scipy.optimize import nnls

    n = int(np.sum(both))
    if settings.prior_sigma is not None:
        return {"prior_sigma": float(settings.prior_sigma), "normal_sigma": 0.0,
                "from": "setting", "texels": n}
    if slant is None or n < _MIN_WEIGHING:
        return {"prior_sigma": PRIOR_SIGMA, "normal_sigma": 0.0,
                "from": "too few texels" if slant is not None else "no sensitivity",
                "texels": n}
    r2 = np.mean(np.log(a[both] / kp[both]), axis=1) ** 2
    v = np.mean(np.where(np.isfinite(data_var[both]), data_var[both], 0.0), axis=1) / 3.0
    x = slant[both]
    edges = np.quantile(x, np.linspace(0.0, 1.0, _WEIGHING_BINS + 1))
    which = np.clip(np.searchsorted(edges, x, side="right") - 1, 0, _WEIGHING_BINS - 1)
    rows, ys = [], []
    for b in range(_WEIGHING_BINS):  # a loop over 8 bins, not texels
        at = which == b
        if at.sum() >= _MIN_WEIGHING // _WEIGHING_BINS:
            rows.append([1.0, float(np.median(x[at]))])
            ys.append(float(np.median(r2[at])) / _MEDIAN_CHI2_1 - float(np.median(v[at])))
    if len(rows) < 2:
        return {"prior_sigma": PRIOR_SIGMA, "normal_sigma": 0.0, "from": "too few texels",
                "texels": n}
    (p2, e2), _ = nnls(np.asarray(rows), np.asarray(ys))
    return {"prior_sigma": float(max(np.sqrt(p2), settings.noise)),
            "normal_sigma": float(np.sqrt(e2)), "from": "data", "texels": n}


def _fill(albedo, known, shape, reference) -> np.ndarray:
    """Texels without a value take their nearest known texel's (in the UV image)."""
    known = known & np.isfinite(albedo).all(axis=1)
    if known.all():
        return albedo
    if not known.any():
        return np.broadcast_to(reference, albedo.shape).copy()
    _, index = ndimage.distance_transform_edt(~known.reshape(shape), return_indices=True)
    nearest = (index[0] * shape[1] + index[1]).reshape(-1)
    return albedo[nearest]


def _reason(constant: bool, channel_stats: list, settings: AlbedoSettings,
            held_out: dict | None = None, kept: dict | None = None) -> str:
    worst = max(channel_stats, key=lambda s: s["spread"] - s["noise"])
    numbers = (f"its albedo varies by {100 * worst['spread']:.1f} % against the photos' "
               f"noise of {100 * worst['noise']:.1f} % (F test p = {worst['p']:.2g} "
               f"over {worst['texels']} measured texels)")
    predicts = ""
    if held_out is not None and held_out["observations"] >= _MIN_HELD_OUT:
        predicts = (f"; from the other photos a texture predicts each photo to "
                    f"{held_out['textured']:.3f}, one color to {held_out['constant']:.3f} "
                    f"(robust RMS log error)")
    if kept is not None:
        errors = (f"squared log error to the texture {kept['to_prior']:.3f}, to one color "
                  f"{kept['to_one']:.3f}, Wilcoxon p = {kept['p']:.2g} and "
                  f"{kept['p_one_colour']:.2g}")
        if kept["agrees"] and held_out is not None and "prior" in held_out \
                and held_out["prior"] <= held_out["textured_at_prior"]:
            because = (f"it predicts each photo at least as well as their own texture does "
                       f"from the other photos ({held_out['prior']:.3f} against "
                       f"{held_out['textured_at_prior']:.3f}, robust RMS log error)")
        elif kept["agrees"]:
            because = (f"it agrees with their pattern ({errors}), but theirs does not "
                       f"predict each photo from the others clearly better than one color")
        else:
            because = (f"they cannot tell its pattern from one color, nor one color from "
                       f"it ({errors})")
        return f"The scan's texture, scaled to the photos: {because}; {numbers}{predicts}."
    if not constant:
        return f"Textured: {numbers}{predicts}."
    if worst["p"] >= settings.p_level:
        return f"One constant color: the variation is not significant; {numbers}{predicts}."
    if worst["spread"] <= worst["noise"]:
        return (f"One constant color: the variation is below the photos' noise; "
                f"{numbers}{predicts}.")
    return (f"One constant color: a texture predicts the photos not clearly better than one "
            f"color does; {numbers}{predicts}.")
