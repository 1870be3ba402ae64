"""The renderer: a Mitsuba 3 scene built from an :class:`~spacefit.scene.assembly.Assembly`
(:mod:`spacefit.rendering.mitsuba_scene`), loaded once and rendered many times, values set in place.

It traces the pixels near the target (:mod:`spacefit.rendering.window`) in passes
(:mod:`spacefit.rendering.sample_passes`), each recorded once and replayed (:mod:`spacefit.rendering.frozen`).
Radiance is in W m^-2 sr^-1 per RGB channel.
"""

from __future__ import annotations

from collections.abc import Collection, Mapping
from concurrent.futures import ThreadPoolExecutor

import numpy as np

from spacefit.errors import check_count
from spacefit.precision import float64
from spacefit.progress import ProgressCallback
from spacefit.rendering.backend import dr, in_variant, mi, resolve_variant, variant_scope
from spacefit.rendering.drjit_values import differentiable, to_value
from spacefit.rendering.frozen import FrozenPasses, splat
from spacefit.rendering.memory import check_memory
from spacefit.rendering.mitsuba_scene import scene_dict
from spacefit.rendering.parts import PartImage
from spacefit.rendering.sample_passes import pass_seeds, render_threads
from spacefit.rendering.window import target_mask, target_window
from spacefit.scene.assembly import Assembly, assemble
from spacefit.scene.overrides import as_parameters
from spacefit.scene.parameters import ATTITUDE, GEOMETRY, POSITION, SUN_ANGLES, scene_value, scene_with_values
from spacefit.scene.sampling import check_sample_count
from spacefit.scene.schema import Scene
from spacefit.scene.sections import MAX_SEED, MAX_SPP, check_scene

# Mitsuba mesh values whose update rebuilds the scene's ray-tracing acceleration structure.
REBUILDS = (".vertex_positions", ".faces")


class Renderer:
    """Only the pixels whose samples can reach the target's silhouette are traced, the rest of the image
    is black; ``crop=False`` traces the whole film, for vertices that will move (the traced pixels are
    fixed when the scene is loaded). Load once and render many times: reloading scenes leaks memory in
    Mitsuba (mitsuba3#1890); change values in place with :meth:`set_values`. Each kind of pass is
    traced at its first render and replayed after until vertices move (:attr:`geometry` counts the
    moves).

    Args:
        scene: the scene (:class:`Scene`).
        variant: a Mitsuba variant; None: the scene's ``render.variant``.
        crop: trace only the pixels near the target.

    Raises:
        InputError: ``scene`` is not a :class:`Scene`, or the render would not fit in memory.

    Example:
        >>> import spacefit as sf
        >>> renderer = sf.Renderer(sf.default_scene().with_values({"render.resolution": [48, 48], "camera.pixel_pitch_mm": 50, "render.spp": 4}))
        >>> before = renderer.render()
        >>> renderer.set_values({"parts.legs.kd": 0.5})
        >>> renderer.current_scene.parts["legs"].material
        Lambert(kd=0.5)
        >>> bool(renderer.render().sum() > before.sum())  # brighter legs
        True
    """

    def __init__(self, scene: Scene | Assembly, variant: str | None = None, crop: bool = True) -> None:
        assembly = scene if isinstance(scene, Assembly) else assemble(check_scene(scene))
        self.variant = resolve_variant(variant or assembly.scene.render.variant)
        self.assembly = assembly
        self.current_scene = assembly.scene
        intr = assembly.intrinsics
        vertices = assembly.scene_vertices
        self.window = target_window(assembly, vertices) if crop else (0, 0, intr.width, intr.height)
        r = assembly.scene.render
        self.memory_bytes = check_memory(intr.width, intr.height, self.window[2] * self.window[3], r.spp)  # the mask traces fewer
        with variant_scope(self.variant):
            objects = scene_dict(assembly, vertices, self.window)
            with ThreadPoolExecutor(1, thread_name_prefix="spacefit-mask") as pool:  # NumPy, while Mitsuba builds its BVH (no GIL)
                traced = pool.submit(target_mask, assembly, vertices, self.window) if crop else None
                self.scene = mi.load_dict(objects)
            self.traced = traced.result() if traced is not None else np.ones(self.window[:1:-1], dtype=bool)
            self._pixels = mi.UInt32(np.flatnonzero(self.traced).astype(np.uint32))
            self.params = mi.traverse(self.scene)
            self.frozen = FrozenPasses()
            self.geometry = 0  # counted up at each rebuild of the acceleration structure (set_params)

    def to_film(self, window_image: np.ndarray) -> np.ndarray:
        """The whole film (height, width, ...) from an image of the rendered window, black outside it."""
        x0, y0, w, h = self.window
        intr = self.assembly.intrinsics
        film = np.zeros((intr.height, intr.width, *window_image.shape[2:]), dtype=np.float32)
        film[y0:y0 + h, x0:x0 + w] = window_image
        return film

    def to_window(self, film_image: np.ndarray) -> np.ndarray:
        """The rendered window's part of a whole-film image (a cotangent, say)."""
        x0, y0, w, h = self.window
        return np.ascontiguousarray(film_image[y0:y0 + h, x0:x0 + w])

    @in_variant
    @float64  # the pose and the W-M heights in float64, rounded to float32 only where Mitsuba takes them
    def set_values(self, values: Mapping[str, float]) -> None:
        """Set values by name in the loaded scene, without reloading it: parameter names (:func:`available_parameters`, e.g. ``{"parts.panels.alpha_x": 0.1, "sun.elevation_deg": 30}``)
        or the scene-file keys they spell another way (``sun.direction``, ``target.attitude_deg``). Each value is checked as
        :func:`load_scene` checks it, with the same message, before anything is
        set. Values set earlier stay: setting one sun angle keeps the other. :attr:`current_scene`
        is the scene the renderer now renders.

        Parameters that move vertices (D, G, rms height, the pose) may move them out of the window: render
        those with ``crop=False``, or build a new Renderer.
        """
        from spacefit.rendering.values import scene_values_fn  # deferred: it imports JAX (0.6 s), which a plain render never needs

        given = as_parameters(self.current_scene, values)
        scene = scene_with_values(self.current_scene, given)  # refused as load_scene refuses it, before anything is set
        # Parameters set as one scene value travel together, so that those not given keep their current values.
        names = []
        for name in given:
            if name in SUN_ANGLES:
                names += SUN_ANGLES
            elif name in (*GEOMETRY, *ATTITUDE, *POSITION):
                names += [*ATTITUDE, *POSITION, *(("wrinkles.D", "wrinkles.G") if scene.wrinkles.enabled else ())]
            else:
                names.append(name)
        names = list(dict.fromkeys(names))
        x = np.array([float(given[n]) if n in given else scene_value(scene, n) for n in names])
        self.set_params({key: np.asarray(value) for key, value in scene_values_fn(self.assembly, names)(x).items()})
        self.current_scene = scene

    @in_variant
    def set_params(self, values: Mapping[str, np.ndarray], grad: Collection[str] = ()) -> None:
        """Set Mitsuba scene values by traverse key (``'panels.bsdf.brdf_0.alpha_u.value'``,
        ``'body.vertex_positions'``; a frame by :func:`to_value`'s numbers), those named in ``grad`` attached
        to Dr.Jit's AD graph (those :func:`differentiable`), the others detached, in the scene's variant
        whatever variant the caller has set. Setting vertex positions rebuilds the ray-tracing
        acceleration structure and counts up :attr:`geometry`."""
        for key, value in values.items():
            self.params[key] = to_value(self.params[key], value)
            if key in grad and differentiable(self.params[key]):
                dr.enable_grad(self.params[key])
        if any(key.endswith(REBUILDS) for key in values):
            self.geometry += 1
        self.params.update()

    @in_variant
    def part_image(self) -> PartImage:
        """The part seen through each pixel's centre (one camera ray per pixel, no sampling)."""
        intr = self.assembly.intrinsics
        x0, y0, w, h = self.window
        sensor = self.scene.sensors()[0]
        index = dr.arange(mi.UInt32, w * h)
        # sample_ray's position sample spans the film's crop window, which is the rendered window
        position = mi.Point2f((mi.Float(index % w) + 0.5) / w, (mi.Float(index // w) + 0.5) / h)
        ray, _ = sensor.sample_ray(0.0, 0.0, position, mi.Point2f(0.5))
        hit = self.scene.ray_intersect(ray)
        names = tuple(self.assembly.parts)
        ids = dr.full(mi.Int32, -1, w * h)
        for shape in self.scene.shapes():
            ids = dr.select(hit.shape == mi.ShapePtr(shape), names.index(shape.id()), ids)
        film = np.full((intr.height, intr.width), -1, dtype=np.int16)
        film[y0:y0 + h, x0:x0 + w] = np.asarray(ids, dtype=np.int16).reshape(h, w)
        return PartImage(film, names)

    @in_variant
    def render(self, spp: int | None = None, seed: int | None = None, progress: ProgressCallback | None = None) -> np.ndarray:
        """Radiance (W m^-2 sr^-1) as a float32 (height, width, 3) array; same seed, same image."""
        r = self.assembly.scene.render
        check_count("spp", spp, 1, MAX_SPP, "as `render.spp`")
        check_count("seed", seed, 0, MAX_SEED, "as `render.seed`")
        spp = r.spp if spp is None else spp
        seed = r.seed if seed is None else seed
        check_sample_count("spp", spp, r.sampler)
        return self.radiance(spp, seed, progress)

    @in_variant
    def radiance(self, spp: int, seed: int, progress: ProgressCallback | None = None) -> np.ndarray:
        """:meth:`render` of checked arguments (the fit's primal renders take this, so that a seed gives
        the image :meth:`render` gives): float32 (height, width, 3), W m^-2 sr^-1."""
        r = self.assembly.scene.render
        passes = pass_seeds(seed, spp, len(self._pixels), r.sampler)
        film = self.scene.sensors()[0].film()
        film.prepare([])
        block = film.create_block()
        block.set_offset(film.crop_offset())
        # every sample weighs alike in the film's filter-weighted mean, whichever pass traced it
        for i, (seed_i, spp_i, start, count) in enumerate(passes):
            self._trace(block, seed_i, spp_i, start, count, r.deterministic)
            if progress is not None:
                progress(i + 1, len(passes))
        film.put_block(block)
        return self.to_film(np.array(film.develop(), dtype=np.float32))

    def _trace(self, block: "mi.ImageBlock", seed: int, spp: int, start: int, count: int, deterministic: bool) -> None:
        """Trace ``spp`` samples in each of the traced pixels ``start`` to ``start + count`` and splat them
        into ``block``, as Mitsuba's own render loop does over a whole window
        (:func:`~spacefit.rendering.frozen.camera_samples`, replayed after its first call).

        The samples are traced on all of Dr.Jit's threads, each sample's value its own; only the
        splatting, where neighbours' samples add into the same pixels, runs on one thread when
        ``deterministic`` (:func:`~spacefit.rendering.sample_passes.render_threads`), in the samples' order: the image is the one a
        render wholly on one thread gives, bit for bit, in 0.54 to 0.62x its time on 2 cores."""
        camera, _, _ = self.frozen.functions(self.geometry)
        position, rgb = camera(self.scene, self._pixels, dr.opaque(mi.UInt32, seed), spp, start, count, self.window[2])
        dr.eval(position, rgb)
        with render_threads(deterministic):
            splat(block, position, rgb)


def render(scene: Scene, progress: ProgressCallback | None = None) -> np.ndarray:
    """Render a scene's radiance image (W m^-2 sr^-1, (height, width, 3) float32). Mitsuba's variant
    is the caller's again after (the API page's notes for integrators). To render one scene many
    times with other values, load it once in a :class:`Renderer`.

    Args:
        scene: the scene (:func:`default_scene`, :func:`load_scene`).
        progress: called with (samples done, samples in all) as the render goes on; None: silent.

    Returns:
        The radiance image; black where no ray meets the target.

    Raises:
        InputError: ``scene`` is not a :class:`Scene` (a path, say: :func:`load_scene` reads files),
            or the render would not fit in memory.

    Example:
        >>> import spacefit as sf
        >>> scene = sf.default_scene().with_values({"render.resolution": [48, 48], "camera.pixel_pitch_mm": 50, "render.spp": 4})
        >>> image = sf.render(scene)
        >>> image.shape, image.dtype
        ((48, 48, 3), dtype('float32'))
    """
    with variant_scope(check_scene(scene).render.variant):
        return Renderer(scene).render(progress=progress)
