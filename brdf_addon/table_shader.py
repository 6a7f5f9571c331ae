"""A Cycles material that shades with a TABULATED (MERL) BRDF for one known distant light.

Cycles has no tabulated-BRDF closure (METHOD.md §8). For one fixed light direction
``l`` (world space) the exact direct shading ``rho(n, l, v) (n.l) E`` is produced by
a Diffuse BSDF (roughness 0: ``albedo / pi (n.l) E`` for a Sun) whose Color is
``pi rho`` read from an image texture, indexed by the Rusinkiewicz bins computed in
nodes from the constant ``l``, the view vector (Geometry "Incoming") and the
shading normal (Geometry "Normal"). Shadows and the cosine come from Cycles; the
Diffuse BSDF colour is not clamped to 1 (checked by the tests with a bright table).
The material is right for that one light only.

Atlas layout (:func:`atlas`, :func:`table_image`): a 16200 x 90 float image, row
(from the bottom, Blender's pixel order) = theta_h bin ``ith``, column =
``180 itd + ipd``; pixel = ``pi rho`` (R, G, B), alpha 1. The node tree addresses
the centre of that pixel, ``u = (180 itd + ipd + 0.5) / 16200``,
``v = (ith + 0.5) / 90``, with "Closest" interpolation, so each lookup reads exactly
one cell (16200 < 16384, Blender's texture size limit).

Tangent-free angles. :func:`core.brdf.merl.half_diff_from_dirs` rotates the light by
``Rz(-phi_h)`` then ``Ry(-theta_h)``; the result ``d`` is the light expressed in
the frame ``(e_theta, e_phi, h)`` with ``e_phi = (z x h) / |z x h|`` and
``e_theta = e_phi x h`` (z = the normal). Hence, in world space and without any
tangent::

    h = normalize(l + v)
    theta_h = acos(n.h),  theta_d = acos(l.h)
    p = n x h  (length sin theta_h > 0, the scale cancels in atan2)
    phi_d = atan2(l.p, l.(p x h)), folded to [0, pi)

identical to merl's angles except where h = n exactly (phi_h undefined, a set of
measure zero). :func:`shade_like_nodes` is the numpy mirror of the node math.
"""

from __future__ import annotations

import numpy as np

from ..core.brdf import merl

_NTH, _NTD, _NPD = merl.SHAPE
WIDTH = _NTD * _NPD  # 16200 columns: 180 itd + ipd
HEIGHT = _NTH  # 90 rows: ith


# ----------------------------------------------------------------------- numpy side
def atlas(table: np.ndarray) -> np.ndarray:
    """(HEIGHT, WIDTH, 4) float32 RGBA atlas of ``table`` ((3, 90, 90, 180) 1/sr,
    NaN = unmeasured, filled first): ``pi rho``, alpha 1, row = ith (bottom first)."""
    table = np.asarray(table, dtype=np.float64)
    if table.shape != (3, *merl.SHAPE):
        raise ValueError(f"table must have shape (3, 90, 90, 180), got {table.shape}")
    if np.isnan(table).any():
        table = merl.fill_unmeasured(table)
    out = np.ones((HEIGHT, WIDTH, 4), dtype=np.float32)
    out[..., :3] = np.moveaxis(np.pi * table.reshape(3, _NTH, WIDTH), 0, -1)
    return out


def node_bins(n, l, v, dtype=np.float64):  # noqa: E741 - the paper's name for the light
    """Bins (N, 3) float ``(ith, itd, ipd)`` exactly as the node tree computes them.

    n, v: (N, 3) unit vectors (or (3,)); l: (3,) or (N, 3). World space."""
    n, l, v = (np.asarray(x, dtype=dtype) for x in (n, l, v))  # noqa: E741
    n, l, v = np.broadcast_arrays(n, l, v)  # noqa: E741

    def dot(a, b):
        return np.sum(a * b, axis=-1)

    h = l + v
    h = h / np.maximum(np.linalg.norm(h, axis=-1, keepdims=True), dtype(1e-30))
    theta_h = np.arccos(np.clip(dot(n, h), -1.0, 1.0))
    theta_d = np.arccos(np.clip(dot(l, h), -1.0, 1.0))
    p = np.cross(n, h)
    q = np.cross(p, h)
    phi_d = np.arctan2(dot(l, p), dot(l, q))
    ith = np.floor(np.sqrt(np.maximum(theta_h / (np.pi / 2), 0.0)) * _NTH)
    itd = np.floor(theta_d / (np.pi / 2) * _NTD)
    ipd = np.floor(np.mod(phi_d / np.pi * _NPD, _NPD))  # floored modulo: [0, 180)
    return np.stack([np.clip(ith, 0, _NTH - 1), np.clip(itd, 0, _NTD - 1),
                     np.clip(ipd, 0, _NPD - 1)], axis=-1)


def texture_uv(bins: np.ndarray) -> np.ndarray:
    """Atlas coordinates (N, 2) of the centres of cells ``bins`` (N, 3)."""
    u = (bins[..., 1] * _NPD + bins[..., 2] + 0.5) / WIDTH
    v = (bins[..., 0] + 0.5) / HEIGHT
    return np.stack([u, v], axis=-1)


def shade_like_nodes(table, n, l, v) -> np.ndarray:  # noqa: E741
    """rho (N, 3) 1/sr as the material reads it: the node math's bins -> atlas
    coordinates -> the Closest texel -> Color / pi (no horizon test: Cycles' own
    cosine and visibility do that)."""
    image = atlas(table)
    uv = texture_uv(node_bins(n, l, v))
    col = np.clip(np.floor(uv[:, 0] * WIDTH), 0, WIDTH - 1).astype(np.int64)
    row = np.clip(np.floor(uv[:, 1] * HEIGHT), 0, HEIGHT - 1).astype(np.int64)
    return image[row, col, :3].astype(np.float64) / np.pi


# ----------------------------------------------------------------------- Blender side
def table_image(table, name: str = "BRDF table") -> bpy.types.Image:  # noqa: F821
    """A NEW 32-bit float, Non-Color image holding :func:`atlas` of ``table``, packed
    (as an uncompressed float EXR, ~23 MB) so that it is saved with the .blend."""
    import bpy

    pixels = atlas(table)
    image = bpy.data.images.new(name, WIDTH, HEIGHT, alpha=True, float_buffer=True,
                                is_data=True)
    image.colorspace_settings.name = "Non-Color"
    image.alpha_mode = "CHANNEL_PACKED"  # alpha is 1 anyway: never premultiply
    image.pixels.foreach_set(pixels.ravel())
    image.update()
    image.pack()  # 32-bit float EXR inside the .blend: survives saving and reloading
    return image


class _Tree:
    """Small helper adding math nodes to a shader node tree, left to right."""

    def __init__(self, tree):
        self.tree = tree
        self.x = -2400

    def _place(self, node):
        node.location = (self.x, 0)
        self.x += 60
        return node

    def _link(self, value, socket):
        if isinstance(value, (int, float)):
            socket.default_value = float(value)
        elif isinstance(value, (tuple, list, np.ndarray)):
            socket.default_value = tuple(float(c) for c in value)
        else:
            self.tree.links.new(value, socket)

    def vec(self, op, a, b=None):
        node = self._place(self.tree.nodes.new("ShaderNodeVectorMath"))
        node.operation = op
        self._link(a, node.inputs[0])
        if b is not None:
            self._link(b, node.inputs[1])
        return node.outputs["Value" if op == "DOT_PRODUCT" else "Vector"]

    def math(self, op, a, b=None):
        node = self._place(self.tree.nodes.new("ShaderNodeMath"))
        node.operation = op
        self._link(a, node.inputs[0])
        if b is not None:
            self._link(b, node.inputs[1])
        return node.outputs["Value"]


def table_material(name: str, table, light_direction) -> bpy.types.Material:  # noqa: F821
    """A NEW material ``name`` shading with ``table`` ((3, 90, 90, 180), 1/sr) for a
    distant light from ``light_direction`` (world space, towards the light; only
    that light is shaded correctly). Stores ``mat["brdf_table_light"]``."""
    import bpy

    light = np.asarray(light_direction, dtype=np.float64)
    light = light / np.linalg.norm(light)
    image = table_image(table, f"{name} table")
    mat = bpy.data.materials.new(name)
    if mat.node_tree is None:  # before Blender 5.0
        mat.use_nodes = True
    tree = mat.node_tree
    tree.nodes.clear()
    t = _Tree(tree)
    geometry = t._place(tree.nodes.new("ShaderNodeNewGeometry"))
    n, v = geometry.outputs["Normal"], geometry.outputs["Incoming"]
    lv = tuple(light)

    h = t.vec("NORMALIZE", t.vec("ADD", lv, v))
    theta_h = t.math("ARCCOSINE", t.vec("DOT_PRODUCT", n, h))
    theta_d = t.math("ARCCOSINE", t.vec("DOT_PRODUCT", lv, h))
    p = t.vec("CROSS_PRODUCT", n, h)
    q = t.vec("CROSS_PRODUCT", p, h)
    phi_d = t.math("ARCTAN2", t.vec("DOT_PRODUCT", lv, p), t.vec("DOT_PRODUCT", lv, q))

    def clamp_floor(x, top):
        return t.math("MINIMUM", t.math("MAXIMUM", t.math("FLOOR", x), 0.0), top - 1)

    ith = clamp_floor(t.math("MULTIPLY", t.math("SQRT", t.math(
        "DIVIDE", theta_h, np.pi / 2)), _NTH), _NTH)
    itd = clamp_floor(t.math("MULTIPLY", theta_d, _NTD / (np.pi / 2)), _NTD)
    ipd = clamp_floor(t.math("FLOORED_MODULO", t.math("MULTIPLY", phi_d, _NPD / np.pi),
                             _NPD), _NPD)
    col = t.math("ADD", t.math("MULTIPLY", itd, _NPD), ipd)
    u = t.math("DIVIDE", t.math("ADD", col, 0.5), WIDTH)
    vv = t.math("DIVIDE", t.math("ADD", ith, 0.5), HEIGHT)
    uv = t._place(tree.nodes.new("ShaderNodeCombineXYZ"))
    tree.links.new(u, uv.inputs["X"])
    tree.links.new(vv, uv.inputs["Y"])

    tex = t._place(tree.nodes.new("ShaderNodeTexImage"))
    tex.image = image
    tex.interpolation = "Closest"
    tex.extension = "EXTEND"
    tree.links.new(uv.outputs["Vector"], tex.inputs["Vector"])
    diffuse = t._place(tree.nodes.new("ShaderNodeBsdfDiffuse"))
    diffuse.inputs["Roughness"].default_value = 0.0
    tree.links.new(tex.outputs["Color"], diffuse.inputs["Color"])
    out = t._place(tree.nodes.new("ShaderNodeOutputMaterial"))
    tree.links.new(diffuse.outputs["BSDF"], out.inputs["Surface"])
    mat["brdf_table_light"] = [float(c) for c in light]
    return mat
