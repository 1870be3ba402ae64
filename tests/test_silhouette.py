"""The traced mask (the target's projected silhouette, dilated by the pixel filter's reach): it never drops a
pixel that a whole-film render lights, and rendering only it changes no pixel's expected value."""

from __future__ import annotations

import numpy as np
import pytest

import spacefit as sf
from spacefit.rendering.silhouette import filter_reach_px, silhouette, traced_pixels

# 96 px at the default field of view; coarse wrinkles for speed.
SMALL = {"render.resolution": [96, 96], "camera.pixel_pitch_mm": 25.0, "wrinkles.spacing_m": 0.1,
         "render.deterministic": False}
# (camera position m, target attitude deg): the default view, a close one cut by the film's edge, oblique poses.
POSES = [
    ([0.0, 0.0, 70.0], [0.0, 0.0, 0.0]),
    ([0.0, 0.0, 12.0], [0.0, 0.0, 0.0]),
    ([0.0, 0.0, 30.0], [35.0, -20.0, 60.0]),
    ([0.0, 0.0, 20.0], [-70.0, 10.0, 150.0]),
    ([0.0, 0.0, 40.0], [90.0, 0.0, 0.0]),
]


def film_mask(renderer: sf.Renderer) -> np.ndarray:
    """The traced mask over the whole film."""
    x0, y0, w, h = renderer.window
    intr = renderer.assembly.intrinsics
    film = np.zeros((intr.height, intr.width), dtype=bool)
    film[y0:y0 + h, x0:x0 + w] = renderer.traced
    return film


@pytest.mark.parametrize("pixel_filter", ["box", "tent"])
@pytest.mark.parametrize(("position", "attitude"), POSES)
def test_mask_never_drops_a_pixel_a_whole_film_render_lights(position, attitude, pixel_filter):
    """With the box filter the mask is the silhouette itself (no reach), so every lit pixel tests its conservativeness;
    with the tent each lit pixel's whole filter support must be traced too (its weights need those samples)."""
    scene = sf.load_scene(None, {**SMALL, "camera.position_m": position, "target.attitude_deg": attitude,
                                 "render.filter": pixel_filter})
    whole = sf.Renderer(scene, crop=False).render(spp=64, seed=1)
    renderer = sf.Renderer(scene)
    traced = film_mask(renderer)
    lit = whole.max(axis=-1) > 0
    assert lit.sum() > 20
    reach = filter_reach_px(1.0 if pixel_filter == "tent" else 0.5)
    # every pixel within the filter's reach of a lit one
    support = np.zeros_like(lit)
    ys, xs = np.nonzero(lit)
    for dy in range(-reach, reach + 1):
        for dx in range(-reach, reach + 1):
            y, x = np.clip(ys + dy, 0, lit.shape[0] - 1), np.clip(xs + dx, 0, lit.shape[1] - 1)
            support[y, x] = True
    assert not np.any(support & ~traced), f"{int((support & ~traced).sum())} px dropped"
    assert traced.mean() < 0.9  # a mask, not the film


def test_masked_render_has_the_whole_film_render_s_expectation():
    """Pixel by pixel (the silhouette's rim included, where the tent weights samples of untraced-looking
    neighbours): the mean of masked renders over seeds against whole-film renders, in standard errors."""
    scene = sf.load_scene(None, {**SMALL, "camera.position_m": [0.0, 0.0, 25.0]})
    masked, whole = sf.Renderer(scene), sf.Renderer(scene, crop=False)
    a = np.stack([masked.render(spp=16, seed=s).mean(axis=-1) for s in range(1, 17)])
    b = np.stack([whole.render(spp=16, seed=s).mean(axis=-1) for s in range(101, 117)])
    lit = (a.max(axis=0) > 0) | (b.max(axis=0) > 0)
    se = np.sqrt((a.var(axis=0, ddof=1) + b.var(axis=0, ddof=1)) / len(a))[lit]
    z = (a.mean(axis=0) - b.mean(axis=0))[lit] / np.maximum(se, 1e-12)
    rim = ~silhouette_of(masked)[lit]
    assert lit.sum() > 300 and rim.sum() > 50
    for part in (z, z[rim]):
        assert abs(part.mean()) < 4 / np.sqrt(part.size) + 0.05
        assert 0.7 < part.std() < 1.4


def silhouette_of(renderer: sf.Renderer) -> np.ndarray:
    """The film's pixels inside the projected silhouette (no reach)."""
    from spacefit.geometry.frames import project

    a = renderer.assembly
    tris = []
    for name, points in a.scene_vertices.items():
        uv, _ = project(points, a.camera, a.intrinsics)
        tris.append(uv[a.faces(name)])
    return silhouette(*mesh(np.concatenate(tris)), a.intrinsics.width, a.intrinsics.height)


def mesh(triangles: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Triangles (n, 3, 2) as a mesh: each corner a vertex of its own, (3n, 2), and faces (n, 3)."""
    return triangles.reshape(-1, 2), np.arange(3 * len(triangles)).reshape(-1, 3)


def test_conservative_rasterisation_of_a_triangle():
    """A triangle within a 3 x 3 px box marks its box; a larger one the pixel squares it touches, and no more."""
    small = silhouette(*mesh(np.array([[[0.2, 0.2], [2.5, 0.2], [0.2, 2.5]]])), 4, 4)
    assert small[:3, :3].all() and not small[3].any() and not small[:, 3].any()
    big = np.array([[[0.5, 0.5], [40.5, 0.5], [0.5, 40.5]]])
    inside = silhouette(*mesh(big), 48, 48)
    # the hypotenuse x + y = 41 touches pixel square (x, 10) while its nearest corner has x + 10 <= 41
    assert inside[10, 31] and not inside[10, 32] and inside[0, 40] and not inside[0, 41]
    traced, lit = traced_pixels(*mesh(big), 48, 48, 1.0)
    assert lit[0, 41] and not lit[0, 42] and traced[0, 42] and not traced[0, 43]


def test_small_triangles_mark_their_boxes_clipped_to_the_film():
    """Triangles within 3 x 3 px mark their whole pixel box, clipped where it crosses the film's edges (some
    lie wholly outside): the union of the boxes, marked one by one."""
    rng = np.random.default_rng(5)
    width, height = 23, 17
    corner = rng.uniform([-4.0, -4.0], [width + 2.0, height + 2.0], size=(400, 1, 2))
    triangles = corner + rng.uniform(0.0, 1.9, size=(400, 3, 2))
    expected = np.zeros((height, width), dtype=bool)
    for tri in triangles:
        (x0, y0), (x1, y1) = np.floor(tri.min(axis=0) - 1e-3).astype(int), np.floor(tri.max(axis=0) + 1e-3).astype(int)
        expected[max(y0, 0):max(y1 + 1, 0), max(x0, 0):max(x1 + 1, 0)] = True
    assert 0 < expected.sum() < expected.size
    np.testing.assert_array_equal(silhouette(*mesh(triangles), width, height), expected)


def test_large_triangles_mark_the_squares_they_touch_in_batches_as_one_by_one(monkeypatch):
    """Triangles larger than the small boxes, some degenerate, some crossing the film's edges, tested in batches
    of a few squares (one triangle alone when it has more): the squares a triangle's own test marks, and the
    mesh's shared vertices give the triangles' own corners."""
    from spacefit.rendering import silhouette as module

    rng = np.random.default_rng(11)
    width, height = 41, 29
    corners = rng.uniform([-6.0, -6.0], [width + 2.0, height + 2.0], size=(30, 1, 2)) + rng.uniform(0.0, 9.0, size=(30, 3, 2))
    corners[:5, 2] = corners[:5, 0] + 0.5 * (corners[:5, 1] - corners[:5, 0])  # degenerate: a segment
    expected = np.zeros((height, width), dtype=bool)
    for tri in corners:
        expected |= silhouette(*mesh(tri[None]), width, height)
    monkeypatch.setattr(module, "SQUARES_PER_BATCH", 50)
    assert 0 < expected.sum() < expected.size
    np.testing.assert_array_equal(silhouette(*mesh(corners), width, height), expected)
    shared = np.unique(corners.reshape(-1, 2), axis=0, return_inverse=True)  # vertices shared between faces
    np.testing.assert_array_equal(silhouette(shared[0], shared[1].reshape(-1, 3), width, height), expected)
