"""The rendered-sphere error used by the benchmarks (core.brdf.metrics.sphere_error)."""

import numpy as np

from brdf_reconstruct.core.brdf import merl, metrics


def _lambert(albedo):
    return np.broadcast_to(np.asarray(albedo, float)[:, None, None, None] / np.pi,
                           (3, *merl.SHAPE)).copy()


def test_sphere_error_of_a_scaled_table_is_the_scale_offset():
    truth = _lambert([0.5, 0.4, 0.3])
    assert metrics.sphere_error(truth, truth) == 0.0
    # every pixel scales by 1.1 -> relative RMSE exactly 0.1, under every light
    assert np.isclose(metrics.sphere_error(1.1 * truth, truth), 0.1, rtol=1e-12)


def test_sphere_lights_are_20_60_100_degrees_from_the_view():
    angles = np.degrees(np.arccos(metrics.SPHERE_LIGHTS @ [0.0, 0.0, 1.0]))
    assert np.allclose(angles, [20.0, 60.0, 100.0])
    assert np.allclose(np.linalg.norm(metrics.SPHERE_LIGHTS, axis=1), 1.0)
