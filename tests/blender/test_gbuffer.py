"""Cycles G-buffers of the scan (brdf_addon.gbuffer) against analytic scenes.

Renders are tiny (at most 96 x 72 px, 1-4 samples); each takes a fraction of a
second.
"""

import math

import numpy as np
import pytest

bpy = pytest.importorskip("bpy")

import bmesh  # noqa: E402
from mathutils import Vector  # noqa: E402

from brdf_reconstruct.brdf_addon import gbuffer  # noqa: E402
from brdf_reconstruct.core.method import gbuffers  # noqa: E402

CENTER = np.array([0.3, -0.2, 0.1])
RADIUS = 1.0
# Icosphere of 6 subdivision levels (20480 faces, edges of ~2.2 degrees): its flat
# faces sag up to ~2e-4 R inside the sphere (measured per mesh by _sag).
SUBDIVISIONS = 6


def _link(obj):
    bpy.context.scene.collection.objects.link(obj)
    return obj


def _sphere():
    mesh = bpy.data.meshes.new("sphere")
    bm = bmesh.new()
    bmesh.ops.create_icosphere(bm, subdivisions=SUBDIVISIONS, radius=RADIUS)
    bm.to_mesh(mesh)
    bm.free()
    mesh.shade_smooth()
    obj = _link(bpy.data.objects.new("sphere", mesh))
    obj.location = CENTER
    return obj


def _camera(location, target, ortho=False, shift=(0.0, 0.0), width=96, height=72):
    data = bpy.data.cameras.new("camera")
    data.lens = 50.0
    data.sensor_fit = "AUTO"
    if ortho:
        data.type = "ORTHO"
        data.ortho_scale = 3.0
    data.shift_x, data.shift_y = shift
    cam = _link(bpy.data.objects.new("camera", data))
    cam.location = location
    direction = Vector(target) - Vector(location)
    cam.rotation_euler = direction.to_track_quat("-Z", "Y").to_euler()
    scene = bpy.context.scene
    scene.camera = cam
    scene.render.resolution_x, scene.render.resolution_y = width, height
    scene.render.resolution_percentage = 100
    bpy.context.view_layer.update()
    return cam


def _sag(obj):
    """How far the mesh's faces dip inside the sphere: R - min face-plane distance."""
    mesh = obj.data
    centres = np.array([p.center for p in mesh.polygons])
    normals = np.array([p.normal for p in mesh.polygons])
    return RADIUS - np.min(np.abs(np.sum(centres * normals, axis=1)))


def _pixel_rays(cam, width, height):
    """Origins and unit directions (H, W, 3), world space, through pixel centres."""
    frame = [np.array(v) for v in cam.data.view_frame(scene=bpy.context.scene)]
    top_right, _, bottom_left, top_left = frame
    u = (np.arange(width) + 0.5) / width
    v = (np.arange(height) + 0.5) / height
    local = (top_left + u[None, :, None] * (top_right - top_left)
             + v[:, None, None] * (bottom_left - top_left))
    matrix = np.array(cam.matrix_world)
    rotation, origin = matrix[:3, :3], matrix[:3, 3]
    if cam.data.type == "ORTHO":
        origins = local @ rotation.T + origin
        directions = np.broadcast_to(rotation @ [0.0, 0.0, -1.0], origins.shape)
    else:
        directions = local @ rotation.T
        origins = np.broadcast_to(origin, directions.shape)
    directions = directions / np.linalg.norm(directions, axis=-1, keepdims=True)
    return origins, directions


def _sphere_hits(origins, directions):
    """Analytic hit mask, points and normals of the sphere (CENTER, RADIUS)."""
    oc = origins - CENTER
    b = np.sum(oc * directions, axis=-1)
    disc = b**2 - (np.sum(oc * oc, axis=-1) - RADIUS**2)
    hit = disc > 0
    t = -b - np.sqrt(np.where(hit, disc, 0.0))
    points = origins + t[..., None] * directions
    return hit, points, (points - CENTER) / RADIUS


def _angle_deg(a, b):
    cos = np.clip(np.sum(a * b, axis=-1) / (np.linalg.norm(a, axis=-1)
                                           * np.linalg.norm(b, axis=-1)), -1, 1)
    return np.degrees(np.arccos(cos))


def _boundary(mask):
    """Pixels of ``mask`` or its complement that touch the other (4-neighbours)."""
    padded = np.pad(mask, 1, mode="edge")
    differs = np.zeros_like(mask)
    for dr, dc in ((0, 1), (2, 1), (1, 0), (1, 2)):
        differs |= padded[dr:dr + mask.shape[0], dc:dc + mask.shape[1]] != mask
    return differs


def _check_sphere(cam, width=96, height=72):
    sphere = _sphere()
    sag = _sag(sphere)
    assert sag < 3e-4
    g = gbuffer.render_gbuffers(sphere, cam, [0.0, 0.0, 1.0])
    assert g.shape == (height, width)
    assert g.normal.shape == (height, width, 3) and g.normal.dtype == np.float64
    assert g.region.dtype == np.int32
    origins, directions = _pixel_rays(cam, width, height)
    hit, points, normals = _sphere_hits(origins, directions)
    # The mask is the analytic projection, up to pixel centres within the sag of
    # the silhouette: only pixels on its boundary may differ.
    assert hit.sum() > 500
    differ = g.mask != hit
    assert not np.any(differ & ~_boundary(hit))
    assert differ.sum() <= 0.02 * hit.sum()
    m = g.mask
    assert np.array_equal(g.region >= 0, m) and np.all(g.region[m] == 0)
    assert np.all(g.normal[~m] == 0) and np.all(g.position[~m] == 0)
    # Rendered point on the mesh: inside the sphere by at most the sag.
    radius = np.linalg.norm(g.position[m] - CENTER, axis=-1)
    assert np.all(np.abs(radius - RADIUS) < 1e-3)
    assert radius.max() < RADIUS + 1e-5 and radius.min() > RADIUS - sag - 1e-5
    # Smooth normal against the radial direction of the rendered point, everywhere.
    error_radial = _angle_deg(g.normal[m], g.position[m] - CENTER)
    assert error_radial.max() < 0.5
    # Against the analytic sphere along the same ray, silhouette included (the
    # mesh's sag moves the hit most at grazing view; measured < 0.5 degree).
    both = m & hit
    assert _angle_deg(g.normal[both], normals[both]).max() < 1.0
    facing = both & (-np.sum(normals * directions, axis=-1) > 0.2)
    error_analytic = _angle_deg(g.normal[facing], normals[facing])
    assert error_analytic.max() < 0.2
    assert np.linalg.norm(g.position[facing] - points[facing], axis=-1).max() < 2e-3
    assert np.allclose(np.linalg.norm(g.normal[m], axis=-1), 1.0)
    return g, error_radial, error_analytic


def test_sphere_perspective():
    cam = _camera((0.3, -6.0, 2.1), CENTER)
    g, radial, analytic = _check_sphere(cam)
    assert np.allclose(g.camera_center, [0.3, -6.0, 2.1])
    assert not g.orthographic and g.window is not None
    # Light from +z: the upper half is lit (no cast shadows on a convex sphere).
    m = g.mask
    cos = g.normal[m] @ [0.0, 0.0, 1.0]
    assert np.all(np.abs(g.visibility[m][cos > 0.05] - 1.0) < 0.01)
    assert np.all(g.visibility[m][cos <= 0.0] == 0.0)


def test_sphere_orthographic():
    cam = _camera((0.3, -6.0, 2.1), CENTER, ortho=True)
    g, _, _ = _check_sphere(cam)
    assert g.orthographic
    # The far camera centre gives the camera axis as the view direction everywhere.
    v = g.camera_center - g.position[g.mask]
    v /= np.linalg.norm(v, axis=-1, keepdims=True)
    axis = np.array(cam.matrix_world.to_3x3().col[2], dtype=np.float64)
    assert np.all(v @ (axis / np.linalg.norm(axis)) > 1 - 1e-9)


def test_sphere_lens_shift():
    # The camera looks at the centre; the shift (in units of the wider side, 96 px)
    # moves the frame right and down, so the sphere appears left of and above the
    # image centre (48, 36) by ~0.15 * 96 and ~0.1 * 96 pixels. _check_sphere
    # compares the mask with the analytic projection through the shifted frame.
    cam = _camera((0.3, -6.0, 0.1), CENTER, shift=(0.15, -0.1))
    g, _, _ = _check_sphere(cam)
    rows, cols = np.nonzero(g.mask)
    assert cols.mean() + 0.5 == pytest.approx(48 - 0.15 * 96, abs=1.0)
    assert rows.mean() + 0.5 == pytest.approx(36 - 0.1 * 96, abs=1.0)


def test_a_scan_with_its_faces_turned_inward_gives_the_same_gbuffers():
    """Photogrammetry meshes often come with their faces wound the wrong way (normals
    pointing into the object). What the camera sees is the same surface, so the
    G-buffers must be those of the outward mesh: normals toward the camera, the same
    points, the same light and shadow."""
    cam = _camera((0.3, -6.0, 2.1), CENTER)
    light = np.array([0.3, -0.5, 0.8]) / np.linalg.norm([0.3, -0.5, 0.8])
    outward = gbuffer.render_gbuffers(_sphere(), cam, light)
    inward = _sphere()
    inward.data.flip_normals()
    inward.data.update()
    assert np.mean(np.array([p.normal for p in inward.data.polygons])
                   * np.array([p.center for p in inward.data.polygons])) < 0  # inward
    g = gbuffer.render_gbuffers(inward, cam, light)
    assert np.array_equal(g.mask, outward.mask)
    m = g.mask
    assert _angle_deg(g.normal[m], outward.normal[m]).max() < 0.01
    assert np.abs(g.position[m] - outward.position[m]).max() < 1e-5
    assert np.abs(g.visibility[m] - outward.visibility[m]).max() < 0.01


def test_visibility_cast_shadow():
    # One object: a 4 x 4 ground plane and a unit box on it; light 45 degrees
    # above the +x horizon, so the box's shadow covers x in [-1.5, -0.5], |y| < 0.5.
    mesh = bpy.data.meshes.new("ground_box")
    bm = bmesh.new()
    bmesh.ops.create_grid(bm, x_segments=1, y_segments=1, size=2.0)
    bmesh.ops.create_cube(bm, size=1.0, matrix=_translation(0.0, 0.0, 0.5))
    bm.to_mesh(mesh)
    bm.free()
    scan = _link(bpy.data.objects.new("scan", mesh))
    # Another object in the light's way: not the scan, so it casts no shadow.
    blocker = _link(bpy.data.objects.new("blocker", _cube_mesh()))
    blocker.location = (1.5, 1.5, 1.0)
    cam = _camera((0.0, -3.0, 6.0), (0.0, 0.0, 0.0), width=80, height=80)
    light = np.array([1.0, 0.0, 1.0]) / math.sqrt(2.0)
    g = gbuffer.render_gbuffers(scan, cam, light)
    x, y, z = np.moveaxis(g.position, -1, 0)
    ground = g.mask & (np.abs(z) < 1e-4)
    shadow = ground & (x > -1.4) & (x < -0.6) & (np.abs(y) < 0.4)
    lit = ground & ((x > 0.6) | (np.abs(y) > 0.6) | (x < -1.6))
    assert shadow.sum() > 20 and lit.sum() > 200
    assert np.all(g.visibility[shadow] < 0.01)
    assert np.all(np.abs(g.visibility[lit] - 1.0) < 0.01)
    # Where the blocker would cast its shadow (x in [-0.5, 1.5], y in [1, 2]): lit.
    behind_blocker = ground & (x > -0.3) & (x < 1.3) & (y > 1.1) & (y < 1.9)
    assert behind_blocker.sum() > 20
    assert np.all(np.abs(g.visibility[behind_blocker] - 1.0) < 0.01)
    # The box's face turned away from the light (-x) is unlit, its top is lit.
    away = g.mask & (np.abs(x + 0.5) < 1e-4) & (z > 0.05)
    assert np.all(g.visibility[away] == 0.0)
    top = g.mask & (np.abs(z - 1.0) < 1e-4)
    assert top.sum() > 20 and np.all(np.abs(g.visibility[top] - 1.0) < 0.01)
    assert np.allclose(g.normal[top], [0.0, 0.0, 1.0], atol=1e-5)


def _translation(x, y, z):
    from mathutils import Matrix

    return Matrix.Translation((x, y, z))


def _cube_mesh():
    mesh = bpy.data.meshes.new("cube")
    bm = bmesh.new()
    bmesh.ops.create_cube(bm, size=1.0)
    bm.to_mesh(mesh)
    bm.free()
    return mesh


def _strip(indices=(0, 1, 7)):
    """Three unit quads in a row along x at z = 0, with the given material indices,
    and two material slots (index 7 is past the last slot)."""
    mesh = bpy.data.meshes.new("strip")
    verts = [(x, y, 0.0) for x in range(4) for y in (0, 1)]
    faces = [(2 * i, 2 * i + 2, 2 * i + 3, 2 * i + 1) for i in range(3)]
    mesh.from_pydata(verts, [], faces)
    for material in ("left", "right"):
        mesh.materials.append(bpy.data.materials.new(material))
    for polygon, index in zip(mesh.polygons, indices, strict=True):
        polygon.material_index = index
    obj = _link(bpy.data.objects.new("strip", mesh))
    obj.location = (-1.5, -0.5, 0.0)
    return obj


def test_region_is_material_slot():
    strip = _strip()
    # Off-centre a little: with the camera on the axis, pixel centres fall exactly
    # on the middle quad's diagonal, where Cycles' shadow ray hits the
    # neighbouring triangle at t = 0 and reports a false shadow.
    cam = _camera((0.013, 0.029, 5.0), (0.013, 0.029, 0.0), ortho=True, width=64, height=32)
    g = gbuffer.render_gbuffers(strip, cam, [0.0, 0.0, 1.0])
    x = g.position[..., 0]
    m = g.mask
    assert np.array_equal(g.region >= 0, m) and np.all(g.region[~m] == -1)
    # Pixels whose centre is inside a quad (away from its edges by 0.02).
    left, middle, right = m & (x < -0.52), m & (x > -0.48) & (x < 0.48), m & (x > 0.52)
    assert left.sum() > 50 and middle.sum() > 50 and right.sum() > 50
    assert np.all(g.region[left] == 0)
    assert np.all(g.region[middle] == 1)
    assert np.all(g.region[right] == 1)  # index 7 renders with the last slot
    # The user's materials are not touched (their pass_index stays 0).
    assert [s.material.pass_index for s in strip.material_slots] == [0, 0]
    assert np.allclose(g.visibility[m], 1.0, atol=1e-4)


def test_region_is_face_set():
    strip = _strip()
    face_sets = strip.data.attributes.new(gbuffer.FACE_SET_ATTRIBUTE, "INT", "FACE")
    face_sets.data.foreach_set("value", [3, 12, 3])  # slots say 0, 1, 1
    cam = _camera((0.013, 0.029, 5.0), (0.013, 0.029, 0.0), ortho=True, width=64, height=32)
    g = gbuffer.render_gbuffers(strip, cam, [0.0, 0.0, 1.0],
                                region_attribute=gbuffer.FACE_SET_ATTRIBUTE)
    x, m = g.position[..., 0], g.mask
    left, middle, right = m & (x < -0.52), m & (x > -0.48) & (x < 0.48), m & (x > 0.52)
    assert np.all(g.region[left] == 3) and np.all(g.region[right] == 3)
    assert np.all(g.region[middle] == 12)  # face-set ids as they are, no slot clamp
    assert np.all(g.region[~m] == -1)
    plain = _strip()  # no face sets: one region
    g = gbuffer.render_gbuffers(plain, cam, [0.0, 0.0, 1.0],
                                region_attribute=gbuffer.FACE_SET_ATTRIBUTE)
    assert set(np.unique(g.region[g.mask])) == {0}


def _uv_strip(second_map=False):
    """The strip with a UV map of its own: u = (x + 1.5) / 3, v = 1 - (y + 0.5)
    (flipped in v, so that a mix-up of u and v or of up and down shows), and
    optionally a second map that is the first shifted by 0.25 in u."""
    strip = _strip()
    layer = strip.data.uv_layers.new(name="scan")
    for loop in strip.data.loops:  # the mesh's own coordinates: world minus (-1.5, -0.5, 0)
        co = strip.data.vertices[loop.vertex_index].co
        layer.data[loop.index].uv = (co.x / 3.0, 1.0 - co.y)
    if second_map:
        other = strip.data.uv_layers.new(name="shifted")
        for loop in strip.data.loops:
            u, v = layer.data[loop.index].uv
            other.data[loop.index].uv = (u + 0.25, v)
        strip.data.uv_layers.active = layer
        layer.active_render = True
    return strip


def test_uv_map_is_rendered_at_each_pixel():
    """The UV G-buffer against the map written on the mesh (an affine function of
    the position, so every pixel's expectation follows from its point)."""
    strip = _uv_strip(second_map=True)
    cam = _camera((0.013, 0.029, 5.0), (0.013, 0.029, 0.0), ortho=True, width=64, height=32)
    g = gbuffer.render_gbuffers(strip, cam, [0.0, 0.0, 1.0], uv=True)
    m = g.mask
    assert g.uv.shape == (32, 64, 2) and m.sum() > 500
    x, y = g.position[..., 0], g.position[..., 1]
    expected = np.stack([(x + 1.5) / 3.0, 1.0 - (y + 0.5)], axis=-1)
    np.testing.assert_allclose(g.uv[m], expected[m], atol=1e-5)
    assert np.isnan(g.uv[~m]).all()
    shifted = gbuffer.render_gbuffers(strip, cam, [0.0, 0.0, 1.0], uv=True, uv_map="shifted")
    np.testing.assert_allclose(shifted.uv[m][:, 0], expected[m][:, 0] + 0.25, atol=1e-5)
    assert gbuffer.render_gbuffers(strip, cam, [0.0, 0.0, 1.0]).uv is None


def test_a_scan_without_the_uv_map_gets_one_sentence():
    cam = _camera((0.013, 0.029, 5.0), (0.013, 0.029, 0.0), ortho=True, width=64, height=32)
    with pytest.raises(ValueError, match="has no UV map, so its texture"):
        gbuffer.render_gbuffers(_strip(), cam, [0.0, 0.0, 1.0], uv=True)
    with pytest.raises(ValueError, match="no UV map named 'other'"):
        gbuffer.render_gbuffers(_uv_strip(), cam, [0.0, 0.0, 1.0], uv=True, uv_map="other")


def test_crop_matches_full_frame():
    cam = _camera((0.3, -6.0, 2.1), CENTER, width=96, height=72)
    sphere = _sphere()
    light = [0.3, -0.5, 0.8]
    cropped = gbuffer.render_gbuffers(sphere, cam, light, crop=True)
    full = gbuffer.render_gbuffers(sphere, cam, light, crop=False)
    assert full.window is None
    r0, r1, c0, c1 = cropped.window
    assert (r1 - r0) * (c1 - c0) < 0.7 * 96 * 72
    outside = np.ones((72, 96), dtype=bool)
    outside[r0:r1, c0:c1] = False
    assert not np.any(cropped.mask[outside])
    assert np.array_equal(cropped.mask, full.mask) and full.mask.sum() > 500
    assert np.array_equal(cropped.region, full.region)
    np.testing.assert_allclose(cropped.normal, full.normal, atol=1e-6)
    np.testing.assert_allclose(cropped.position, full.position, atol=1e-6)
    np.testing.assert_allclose(cropped.visibility, full.visibility, atol=1e-6)


def test_more_samples_stay_near_the_pixel_centre():
    # One sample sits at the pixel centre; more are drawn from the 0.01 px filter,
    # with rare outliers (measured: 6 of ~1300 pixels turned by 0.1-0.9 degree,
    # the rest by ~0.003). A box filter would jitter over the whole pixel.
    cam = _camera((0.3, -6.0, 2.1), CENTER)
    sphere = _sphere()
    one = gbuffer.render_gbuffers(sphere, cam, [0.0, 0.0, 1.0])
    four = gbuffer.render_gbuffers(sphere, cam, [0.0, 0.0, 1.0], render_samples=4)
    edge = _boundary(one.mask)
    assert not np.any((one.mask != four.mask) & ~edge)
    inner = one.mask & ~edge
    turn = _angle_deg(one.normal[inner], four.normal[inner])
    assert np.median(turn) < 0.01 and np.mean(turn > 0.1) < 0.02 and turn.max() < 2.0


def test_a_pixel_footprint_holds_the_sphere_at_each_points_own_ray():
    """The footprint (G-buffers at 2 x the photo's size, grouped per photo pixel) gives
    the analytic sphere's normal along the ray through each of a pixel's 2 x 2
    points (offsets of a quarter pixel), not the centre's: the points of one pixel
    differ by the sphere's turn over half a pixel, and their mean is the centre's."""
    width, height = 96, 72
    cam = _camera((0.3, -6.0, 2.1), CENTER, width=width, height=height)
    sphere = _sphere()
    light = [0.0, 0.0, 1.0]
    centre = gbuffer.render_gbuffers(sphere, cam, light)
    fine = gbuffer.render_gbuffers(sphere, cam, light, resolution=(2 * width, 2 * height))
    fp = gbuffers.footprint_normals(fine, 2)
    assert fp.shape == (height, width, 4, 3)
    origins, directions = _pixel_rays(cam, 2 * width, 2 * height)
    hit, _, normals = _sphere_hits(origins, directions)
    hit = hit.reshape(height, 2, width, 2).transpose(0, 2, 1, 3).reshape(height, width, 4)
    normals = normals.reshape(height, 2, width, 2, 3).transpose(0, 2, 1, 3, 4).reshape(
        height, width, 4, 3)
    on = np.isfinite(fp).all(axis=-1)
    assert np.array_equal(on, np.linalg.norm(fp, axis=-1) > 0.5, equal_nan=False)
    # inside the silhouette (all four points on the sphere and facing the camera)
    facing = -np.sum(normals * directions.reshape(height, 2, width, 2, 3).transpose(
        0, 2, 1, 3, 4).reshape(height, width, 4, 3), axis=-1) > 0.2
    inner = (on & hit & facing).all(axis=-1) & centre.mask
    assert inner.sum() > 500
    assert _angle_deg(fp[inner], normals[inner]).max() < 0.2
    # the points are not the centre's normal: they spread over the pixel
    spread = _angle_deg(fp[inner][:, 0], fp[inner][:, 3])
    assert np.median(spread) > 0.3
    mean = fp[inner].mean(axis=1)
    assert np.median(_angle_deg(mean, centre.normal[inner])) < 0.1 * np.median(spread)
    # a pixel on the silhouette has points off the sphere (NaN), the rest unit normals
    assert np.any(~on.all(axis=-1) & on.any(axis=-1))
    assert np.allclose(np.linalg.norm(fp[on], axis=-1), 1.0)


def test_object_outside_the_frame():
    sphere = _sphere()
    sphere.location = (10.0, 0.0, 0.0)
    cam = _camera((0.0, -6.0, 0.0), (0.0, 0.0, 0.0), ortho=True, width=32, height=24)
    g = gbuffer.render_gbuffers(sphere, cam, [0.0, 0.0, 1.0])
    assert g.shape == (24, 32) and not g.mask.any() and np.all(g.region == -1)
    # Behind a perspective camera: the box cannot be projected, the full frame
    # is rendered and holds nothing.
    cam = _camera((0.0, -6.0, 0.0), (0.0, -12.0, 0.0), width=32, height=24)
    g = gbuffer.render_gbuffers(_sphere(), cam, [0.0, 0.0, 1.0])
    assert g.window is None and not g.mask.any()


def _snapshot():
    """What a render must leave as it was: data-block counts and names, the
    scene's settings, links and the objects' materials."""
    scene = bpy.context.scene
    blocks = {}
    for attr in dir(bpy.data):
        collection = getattr(bpy.data, attr)
        if isinstance(collection, bpy.types.bpy_prop_collection):
            blocks[attr] = sorted(block.name for block in collection)
    render, cycles = scene.render, scene.cycles
    settings = (render.engine, render.resolution_x, render.resolution_y,
                render.resolution_percentage, render.film_transparent, render.use_border,
                render.filepath, render.image_settings.file_format, cycles.samples,
                cycles.pixel_filter_type, cycles.filter_width, cycles.max_bounces,
                cycles.use_denoising, scene.frame_current)
    layers = [(vl.name, vl.material_override, vl.use_pass_normal, len(vl.aovs))
              for vl in scene.view_layers]
    objects = {o.name: (tuple(o.location), [c.name for c in o.users_collection],
                        [s.name for s in o.users_scene],
                        [(s.link, s.material and s.material.name) for s in o.material_slots])
               for o in bpy.data.objects}
    materials = {m.name: (m.pass_index, len(m.node_tree.nodes) if m.node_tree else 0)
                 for m in bpy.data.materials}
    return (blocks, settings, layers, objects, materials, bpy.context.scene.name,
            scene.camera.name, scene.world and scene.world.name, bpy.context.view_layer.name)


def test_user_scene_is_unchanged(tmp_path):
    scene = bpy.context.scene
    scene.world = bpy.data.worlds.new("world")
    scene.render.engine = "BLENDER_EEVEE"
    scene.render.filepath = "//frames/"
    strip = _strip()
    other = _link(bpy.data.objects.new("other", _cube_mesh()))
    other.location = (0.0, 0.0, 3.0)
    cam = _camera((0.0, 0.0, 5.0), (0.0, 0.0, 0.0), ortho=True, width=50, height=40)
    scene.render.resolution_percentage = 50
    user_cam = _link(bpy.data.objects.new("user camera", bpy.data.cameras.new("user")))
    scene.camera = user_cam
    # The camera's own size wins over the scene's.
    cam["brdf_width"], cam["brdf_height"] = 40, 30
    before = _snapshot()
    g = gbuffer.render_gbuffers(strip, cam, [0.0, 0.0, 1.0], tmpdir=tmp_path)
    assert g.shape == (30, 40) and g.mask.any()
    gbuffer.render_gbuffers(strip, cam, [0.0, 0.0, 1.0], crop=False, tmpdir=tmp_path,
                            resolution=(20, 10))
    assert _snapshot() == before
    assert "Render Result" not in bpy.data.images
    assert list(tmp_path.iterdir()) == []
    # Scene resolution with its percentage when the camera has no size.
    del cam["brdf_width"], cam["brdf_height"]
    assert gbuffer.render_gbuffers(strip, cam, [0.0, 0.0, 1.0]).shape == (20, 25)
    assert _snapshot() == before


def test_invalid_arguments():
    sphere = _sphere()
    cam = _camera((0.0, -6.0, 0.0), (0.0, 0.0, 0.0), width=16, height=16)
    with pytest.raises(ValueError, match="mesh"):
        gbuffer.render_gbuffers(cam, cam, [0.0, 0.0, 1.0])
    with pytest.raises(ValueError, match="camera"):
        gbuffer.render_gbuffers(sphere, sphere, [0.0, 0.0, 1.0])
    with pytest.raises(ValueError, match="light_direction"):
        gbuffer.render_gbuffers(sphere, cam, [0.0, 0.0, 0.0])
    with pytest.raises(ValueError, match="light_direction"):
        gbuffer.render_gbuffers(sphere, cam, [0.0, np.nan, 1.0])
    with pytest.raises(ValueError, match="samples"):
        gbuffer.render_gbuffers(sphere, cam, [0.0, 0.0, 1.0], render_samples=0)
    with pytest.raises(ValueError, match="resolution"):
        gbuffer.render_gbuffers(sphere, cam, [0.0, 0.0, 1.0], resolution=(0, 16))
    with pytest.raises(ValueError, match="device"):
        gbuffer.render_gbuffers(sphere, cam, [0.0, 0.0, 1.0], device="TPU")
    cam.data.type = "PANO"
    with pytest.raises(ValueError, match="perspective or orthographic"):
        gbuffer.render_gbuffers(sphere, cam, [0.0, 0.0, 1.0])


def test_nonfinite_passes_become_background():
    # What Cycles may write on a degenerate face: NaN / Inf in any pass.
    shape = (2, 3)
    layer = "ViewLayer"
    channels = {f"{layer}.Combined.A": np.ones(shape, np.float32)}
    normal = np.zeros((*shape, 3), np.float32)
    normal[..., 2] = 1.0
    for k, c in enumerate("XYZ"):
        channels[f"{layer}.Normal.{c}"] = normal[..., k].copy()
        channels[f"{layer}.Position.{c}"] = np.ones(shape, np.float32)
    for c in "RGB":
        channels[f"{layer}.Diffuse Direct.{c}"] = np.full(shape, 0.5, np.float32)
    channels[f"{layer}.brdf_region.X"] = np.ones(shape, np.float32)
    channels[f"{layer}.Normal.X"][0, 0] = np.nan
    channels[f"{layer}.Position.Y"][0, 1] = np.inf
    channels[f"{layer}.Diffuse Direct.G"][0, 2] = np.nan
    channels[f"{layer}.brdf_region.X"][1, 0] = -np.inf
    channels[f"{layer}.Combined.A"][1, 1] = np.nan
    g = gbuffers.decode(channels, light=np.array([0.0, 0.0, 1.0]), slots=2,
                        center=np.zeros(3), ortho=False, window=None)
    assert g.mask.tolist() == [[False, False, False], [False, False, True]]
    assert np.all(g.region == [[-1, -1, -1], [-1, -1, 1]])
    for a in (g.normal, g.position, g.visibility):
        assert np.all(np.isfinite(a))
    assert g.visibility[1, 2] == pytest.approx(0.5)
    assert np.all(g.visibility[~g.mask] == 0) and np.all(g.normal[~g.mask] == 0)


def test_exr_round_trip(tmp_path):
    """read_multilayer_exr places a part's data window inside the display window."""
    import OpenImageIO as oiio

    path = str(tmp_path / "window.exr")
    spec = oiio.ImageSpec(3, 2, 1, oiio.FLOAT)
    spec.channelnames = ("ViewLayer.Depth.Z",)
    spec.x, spec.y = 1, 2
    spec.full_x, spec.full_y, spec.full_width, spec.full_height = 0, 0, 5, 4
    out = oiio.ImageOutput.create(path)
    assert out.open(path, spec)
    out.write_image(np.arange(6, dtype=np.float32).reshape(2, 3, 1))
    out.close()
    depth = gbuffer.read_multilayer_exr(path)["ViewLayer.Depth.Z"]
    expected = np.zeros((4, 5), np.float32)
    expected[2:4, 1:4] = np.arange(6).reshape(2, 3)
    np.testing.assert_array_equal(depth, expected)
