"""The measured MERL pack for tests and benches: where it is, each material's class,
and cross-validation folds that never score a material the basis was built from.

No bpy. The pack is ``merl_nbrdf.npz`` in ``../shared/data`` beside the repository,
or in ``$BRDF_SHARED_DATA``; where neither holds it, the copy the extension ships
(``nbrdf.BUNDLED_PACK``, the same file), so that a fresh clone tests it too.
"""

from __future__ import annotations

import dataclasses
import os
import pathlib

import numpy as np

from brdf_reconstruct.core.brdf import nbrdf

DATA = pathlib.Path(os.environ.get(
    "BRDF_SHARED_DATA", pathlib.Path(__file__).resolve().parents[2] / "shared" / "data"))
PACK = DATA / "merl_nbrdf.npz" if (DATA / "merl_nbrdf.npz").is_file() else nbrdf.BUNDLED_PACK

CLASSES = ("metal", "paint", "plastic", "fabric", "wood", "stone", "rubber")
# MERL names that the name rules below would not place (or would place wrongly)
_NAMED = {
    "aluminium": "metal", "brass": "metal", "chrome": "metal", "ss440": "metal",
    "steel": "metal", "black-oxidized-steel": "metal", "grease-covered-steel": "metal",
    "two-layer-gold": "metal", "two-layer-silver": "metal", "tungsten-carbide": "metal",
    "chrome-steel": "metal", "nickel": "metal",
    "colonial-maple-223": "wood", "fruitwood-241": "wood", "ipswich-pine-221": "wood",
    "natural-209": "wood", "pickled-oak-260": "wood", "cherry-235": "wood",
    "special-walnut-224": "wood",
    "alumina-oxide": "stone", "aventurnine": "stone", "black-obsidian": "stone",
    "hematite": "stone", "silicon-nitrade": "stone", "white-marble": "stone",
    "blue-rubber": "rubber", "green-latex": "rubber", "neoprene-rubber": "rubber",
    "pure-rubber": "rubber", "white-diffuse-bball": "rubber", "polyurethane-foam": "rubber",
    "nylon": "plastic", "polyethylene": "plastic", "pvc": "plastic", "teflon": "plastic",
    "delrin": "plastic",
}


def material_class(name: str) -> str:
    """One of :data:`CLASSES` for a MERL material name."""
    if name in _NAMED:
        return _NAMED[name]
    for word, kind in (("fabric", "fabric"), ("velvet", "fabric"), ("paint", "paint"),
                       ("plastic", "plastic"), ("acrylic", "plastic"),
                       ("phenolic", "plastic"), ("rubber", "rubber"), ("metal", "metal")):
        if word in name:
            return kind
    raise ValueError(f"no class known for MERL material {name}")


def folds(names, k: int = 5, seed: int = 0) -> list[list[str]]:
    """``k`` disjoint held-out sets covering ``names``, each class spread over the
    folds (stratified, shuffled by ``seed``): fold f's basis is built from the
    others, so no material is scored by a basis that saw it."""
    rng = np.random.default_rng(seed)
    out: list[list[str]] = [[] for _ in range(k)]
    position = 0
    for kind in CLASSES:
        members = sorted(n for n in names if material_class(n) == kind)
        for n in rng.permutation(members):
            out[position % k].append(str(n))
            position += 1
    return [sorted(f) for f in out]


def held_out(basis, name: str) -> str:
    """``name``, after checking that ``basis`` was not built from it (its
    ``info["materials"]``): ValueError if it was, so a bench can never score a
    material with a basis that saw it. A basis that does not list its materials
    is refused too."""
    materials = basis.info.get("materials")
    if materials is None:
        raise ValueError("the basis does not list its training materials, so it cannot "
                         f"be shown that {name} is held out")
    if name in materials:
        raise ValueError(f"{name} is one of the basis' {len(materials)} training "
                         "materials: a material is never scored by a basis built from it")
    return name


def fold_training(names, name: str, k: int = 5) -> list[str]:
    """The training materials of the fold (:func:`folds` of ``names``, ``k`` folds,
    seed 0) that holds ``name`` out: what a basis that may score ``name`` is built
    from. ValueError if ``name`` is not among ``names``."""
    for held in folds(names, k=k):
        if name in held:
            return [n for n in names if n not in held]
    raise ValueError(f"{name} is not one of the {len(names)} measured materials")


def one_per_class(names, seed: int = 0) -> list[str]:
    """One material of each of :data:`CLASSES`, drawn at random with ``seed`` (not
    picked by hand): the measured held-out set of the benches whose runs cost
    seconds each (the bunny capture's), where all 80 would take hours. In class
    order."""
    rng = np.random.default_rng(seed)
    out = []
    for kind in CLASSES:
        members = sorted(n for n in names if material_class(n) == kind)
        out.append(str(members[rng.integers(len(members))]))
    return out


def pack_without(name: str, folder) -> pathlib.Path:
    """A pack file in ``folder`` holding the networks of :func:`fold_training` for
    ``name`` (the pack's materials outside the fold that holds it out): given to a
    batch run as ``$BRDF_MEASURED_PACK``, the product's own override, so that the
    run's measured basis never saw ``name``. Written once (temporary name, then
    renamed)."""
    pack = nbrdf.load(PACK)
    train = fold_training(pack.names, name)
    index = [pack.index(n) for n in train]
    folder = pathlib.Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    path = folder / f"pack_without_fold_of_{name}.npz"
    if not path.is_file():
        tmp = folder / f".{path.stem}.tmp.npz"
        layers = {f.name: getattr(pack, f.name)[index] for f in dataclasses.fields(pack)
                  if f.name != "names"}
        np.savez(tmp, names=np.array(train), **layers)
        os.replace(tmp, path)
    return path
