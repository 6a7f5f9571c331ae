"""Direct-light shading of tabulated BRDFs in numpy, and the test sphere.

Radiance from one distant light of irradiance E (normal incidence) is
``L = rho(n, l, v) * max(n.l, 0) * E``; no shadows or interreflection here (a
caller with a visibility buffer multiplies it in).
"""

from __future__ import annotations

import numpy as np

from . import merl

# The light of the benchmark spheres: camera space, +z towards the viewer.
REFERENCE_LIGHT = np.array([1.0, 1.0, 1.0]) / np.sqrt(3.0)


def view_directions(camera_center: np.ndarray, points: np.ndarray) -> np.ndarray:
    """Unit vectors (N, 3) from surface points (N, 3) towards a camera centre (3,),
    same frame; zero where a point coincides with the centre."""
    to_camera = np.asarray(camera_center, dtype=np.float64)[None, :] - points
    length = np.linalg.norm(to_camera, axis=1, keepdims=True)
    return np.divide(to_camera, length, out=np.zeros_like(to_camera), where=length > 0.0)


def shade(
    table: np.ndarray,
    n: np.ndarray,
    l: np.ndarray,  # noqa: E741 - the paper's name for the light direction
    v: np.ndarray,
    irradiance=1.0,
    interpolation: str = "nearest",
) -> np.ndarray:
    """Radiance (N, 3) of surface points lit by one distant light.

    table: (3, 90, 90, 180) BRDF, 1/sr. n, l, v: (N, 3) unit vectors in one frame
    (l and v may also be a single (3,) direction). irradiance: scalar or RGB,
    W/m^2 on a surface facing the light. Returns W/(m^2 sr), finite, >= 0.
    """
    n = np.asarray(n, dtype=np.float64).reshape(-1, 3)
    l = np.broadcast_to(np.asarray(l, dtype=np.float64), n.shape)  # noqa: E741
    v = np.broadcast_to(np.asarray(v, dtype=np.float64), n.shape)
    rho = merl.evaluate(table, n, l, v, interpolation=interpolation)
    cos = np.clip(np.sum(n * l, axis=1), 0.0, None)
    return rho * cos[:, None] * np.asarray(irradiance, dtype=np.float64)


def sphere_normals(resolution: int) -> tuple[np.ndarray, np.ndarray]:
    """Unit normals of a sphere seen by an orthographic camera looking down -z.

    Returns normals (H, W, 3) (zero outside) and mask (H, W) bool, H = W =
    resolution; pixel centres span [-1, 1], image row 0 at +y. View v = +z.
    """
    c = (np.arange(resolution) + 0.5) / resolution * 2.0 - 1.0
    x, y = np.meshgrid(c, -c)
    r2 = x**2 + y**2
    mask = r2 < 1.0
    z = np.sqrt(np.clip(1.0 - r2, 0.0, None))
    normals = np.where(mask[..., None], np.stack([x, y, z], axis=-1), 0.0)
    return normals, mask


def render_sphere(
    table: np.ndarray,
    light: np.ndarray,
    resolution: int = 96,
    irradiance=1.0,
    interpolation: str = "nearest",
) -> np.ndarray:
    """Image (H, W, 3) of a sphere with the BRDF ``table`` under a distant light.

    light: (3,) direction towards the light in camera space (+z towards the
    viewer). Background pixels are 0.
    """
    light = np.asarray(light, dtype=np.float64)
    light = light / np.linalg.norm(light)
    normals, mask = sphere_normals(resolution)
    image = np.zeros((resolution, resolution, 3))
    image[mask] = shade(
        table, normals[mask], light, (0.0, 0.0, 1.0), irradiance, interpolation
    )
    return image
