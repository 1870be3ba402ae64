"""Mitsuba 3 scene built from an :class:`~spacefit.scene.assembly.Assembly`, loaded once.

Radiance is in W m^-2 sr^-1 per RGB channel: the sun's irradiance is the same in each channel, so a
Lambert part with kd 0.2 facing a sun of 5 W m^-2 reads 0.2 * 5 / pi in every channel.
"""

from __future__ import annotations

import math
from collections.abc import Collection, Iterator, Mapping
from concurrent.futures import ThreadPoolExecutor
from contextlib import contextmanager

import numpy as np

from spacefit.errors import check_count
from spacefit.geometry.frames import project
from spacefit.materials import Material
from spacefit.precision import float64
from spacefit.progress import ProgressCallback
from spacefit.rendering.backend import dr, in_variant, mi, resolve_variant, variant_scope
from spacefit.rendering.frozen import FrozenPasses, splat
from spacefit.rendering.materials import bsdf_dict
from spacefit.rendering.memory import MAX_SAMPLES_PER_PASS, check_memory
from spacefit.rendering.parts import PartImage
from spacefit.scene.assembly import Assembly, assemble
from spacefit.scene.overrides import as_parameters
from spacefit.scene.parameters import ATTITUDE, GEOMETRY, POSITION, SUN_ANGLES, scene_value, scene_with_values
from spacefit.rendering.silhouette import traced_pixels
from spacefit.scene.schema import Scene
from spacefit.scene.sections import FAR_CLIP_M, FILTER_RADIUS_PX, MAX_SEED, MAX_SPP, NEAR_CLIP_M, check_scene
from spacefit.scene.sampling import check_sample_count, split_sample_count

# Mitsuba mesh values whose update rebuilds the scene's ray-tracing acceleration structure.
REBUILDS = (".vertex_positions", ".faces")

# Pixels around the target's projected box that its light can still reach: the tent filter's
# radius (1 px) and one for rounding.
CROP_MARGIN_PX = 2


def mesh_object(name: str, vertices: np.ndarray, faces: np.ndarray, uv: np.ndarray | None, material: Material) -> "mi.Mesh":
    """A flat-shaded Mitsuba mesh with its BSDF; uv (if any) fixes the tangent along dp/du."""
    props = mi.Properties()
    props["bsdf"] = mi.load_dict(bsdf_dict(material))
    mesh = mi.Mesh(name, len(vertices), len(faces), props, has_vertex_normals=False, has_vertex_texcoords=uv is not None)
    params = mi.traverse(mesh)
    params["vertex_positions"] = mi.Float(np.ravel(vertices).astype(np.float32))
    params["faces"] = mi.UInt32(np.ravel(faces).astype(np.uint32))
    if uv is not None:
        params["vertex_texcoords"] = mi.Float(np.ravel(uv).astype(np.float32))
    params.update()
    return mesh


def target_window(assembly: Assembly, vertices: Mapping[str, np.ndarray]) -> tuple[int, int, int, int]:
    """The film window (x0, y0, width, height), px, outside which the image is black: the projected
    box of every vertex of the target (world ``vertices`` per part, m), widened by
    :data:`CROP_MARGIN_PX` and clipped to the film. In black space nothing else is lit. The whole
    film when a vertex lies behind the camera, where the projected box means nothing."""
    intr = assembly.intrinsics
    uv, depth = project(np.concatenate(list(vertices.values())), assembly.camera, intr)
    size = np.array([intr.width, intr.height])
    if not np.all(depth > 0):
        return 0, 0, intr.width, intr.height
    lo = np.clip(np.floor([u.min() for u in uv.T]) - CROP_MARGIN_PX, 0, size - 1).astype(int)  # by column: 50x faster
    hi = np.clip(np.ceil([u.max() for u in uv.T]) + CROP_MARGIN_PX, lo + 1, size).astype(int)
    return int(lo[0]), int(lo[1]), int(hi[0] - lo[0]), int(hi[1] - lo[1])


def target_mask(assembly: Assembly, vertices: Mapping[str, np.ndarray], window: tuple[int, int, int, int]) -> np.ndarray:
    """(height, width) bool over the film ``window``: the pixels a render traces, those whose samples
    can reach a pixel the target lights (:func:`spacefit.rendering.silhouette.traced_pixels`: its
    projected triangles, world ``vertices`` per part, m, dilated twice by the filter's reach). The whole
    window when a vertex lies behind the camera."""
    x0, y0, w, h = window
    uv, depth = project(np.concatenate(list(vertices.values())), assembly.camera, assembly.intrinsics)
    if not np.all(depth > 0):
        return np.ones((h, w), dtype=bool)
    starts = np.cumsum([0, *(len(points) for points in vertices.values())])
    faces = np.concatenate([assembly.faces(name) + start for name, start in zip(vertices, starts)])
    return traced_pixels(uv - [x0, y0], faces, w, h, FILTER_RADIUS_PX[assembly.scene.render.filter])[0]


def scene_dict(assembly: Assembly, vertices: Mapping[str, np.ndarray], window: tuple[int, int, int, int]) -> dict:
    """The Mitsuba scene dictionary: path tracer, pinhole camera, tent-filtered film rendering the
    pixel ``window`` (x0, y0, width, height) of the image, sun, and the parts at world ``vertices`` (m)."""
    s = assembly.scene
    cam, intr = assembly.camera, assembly.intrinsics
    # Mitsuba's principal point offset is a fraction of the film, positive towards -u / -v.
    sensor = {
        "type": "perspective",
        "fov": math.degrees(intr.fov_x),
        "fov_axis": "x",
        "near_clip": NEAR_CLIP_M,
        "far_clip": FAR_CLIP_M,
        "principal_point_offset_x": -intr.principal_offset[0] / intr.width,
        "principal_point_offset_y": -intr.principal_offset[1] / intr.height,
        "to_world": mi.ScalarTransform4f(cam.mitsuba_to_world()),
        "sampler": {"type": s.render.sampler, "sample_count": split_sample_count(s.render.sampler, s.render.spp)[0]},
        "film": {
            "type": "hdrfilm",
            "width": intr.width,
            "height": intr.height,
            "pixel_format": "rgb",
            "rfilter": {"type": s.render.filter},
            "crop_offset_x": window[0],
            "crop_offset_y": window[1],
            "crop_width": window[2],
            "crop_height": window[3],
        },
    }
    max_depth = s.render.depth + 1
    d = {
        "type": "scene",
        # Russian roulette off: every path runs to the stated depth, as in the thesis's tracer.
        "integrator": {"type": "path", "max_depth": max_depth, "rr_depth": max_depth + 1},
        "sensor": sensor,
        "sun": {"type": "directional", "direction": assembly.sun_direction.tolist(), "irradiance": s.sun.irradiance_w_m2},
    }
    for name, part in assembly.parts.items():
        uv = None if name in assembly.refinements else part.uv
        d[name] = mesh_object(name, vertices[name], assembly.faces(name), uv, assembly.materials[name])
    return d


def mitsuba_scene_dict(scene: Scene) -> dict:
    """The Mitsuba scene dictionary of ``scene`` (the whole film): the integrator, camera, film and
    sun as dictionaries, each part an ``mi.Mesh`` with its BSDF. The meshes belong to the variant the
    scene renders with (``llvm_ad_rgb``, ``cuda_ad_rgb`` on a GPU): load the dictionary in it,
    ``with mi.variant_context("llvm_ad_rgb"): mi.load_dict(d)``."""
    assembly = assemble(check_scene(scene))
    intr = assembly.intrinsics
    with variant_scope(scene.render.variant):
        return scene_dict(assembly, assembly.scene_vertices, (0, 0, intr.width, intr.height))


def pass_seed(seed: int, i: int) -> int:
    """The seed of pass ``i`` of a render seeded ``seed`` (pass 0 keeps it)."""
    return (seed + i * 0x9E3779B1) % (1 << 32)


def pass_seeds(seed: int, spp: int, pixels: int, sampler: str = "independent") -> list[tuple[int, int, int, int]]:
    """Split a render of ``pixels`` pixels at ``spp`` into passes: the counts the sampler takes
    (:func:`~spacefit.scene.schema.split_sample_count`), each over pixel ranges of at most
    :data:`MAX_SAMPLES_PER_PASS` samples (one pixel at least), a pixel's samples of one count in one
    pass so that a stratifying sampler keeps its pattern: (seed, spp, first pixel, pixels) each."""
    passes = []
    for count in split_sample_count(sampler, spp):
        n = max(1, math.ceil(pixels / max(1, MAX_SAMPLES_PER_PASS // count)))
        sizes = [pixels // n + (i < pixels % n) for i in range(n)]
        passes += [(count, int(start), size) for start, size in zip(np.cumsum([0, *sizes[:-1]]), sizes)]
    return [(pass_seed(seed, i), count, start, size) for i, (count, start, size) in enumerate(passes)]


@contextmanager
def render_threads(deterministic: bool) -> Iterator[None]:
    """Render on one thread when ``deterministic``: the film then adds samples in a fixed order.

    Parallel renders differ by float32 rounding (about 1e-7 relative) from call to call, which
    also breaks common random numbers for finite differences of small effects.
    """
    threads = dr.thread_count()
    resize = deterministic and threads > 1
    if resize:
        # Kernels run asynchronously on the LLVM backend: resizing the thread pool under a running one
        # crashed (SIGSEGV in set_thread_count) on a loaded machine, and one queued would run on the new size.
        dr.sync_thread()
        dr.set_thread_count(1)
    try:
        yield
    finally:
        if resize:
            dr.sync_thread()
            dr.set_thread_count(threads)


@contextmanager
def errors_only() -> Iterator[None]:
    """Mitsuba logs only errors inside the block. Its SIGINT handler logs "Received interrupt signal,
    winding down.." as a warning, though a wavefront render does not wind down: the signal is the
    caller's to report (:func:`spacefit.interrupts.run_interruptibly`). The logger is one for all
    threads, so the block's own warnings are dropped too: keep it to the render call."""
    logger = mi.logger()
    level = logger.log_level()
    logger.set_log_level(mi.LogLevel.Error)
    try:
        yield
    finally:
        logger.set_log_level(level)


@contextmanager
def kernel_log() -> Iterator[dict[str, float]]:
    """Count the Dr.Jit kernels launched inside the block; the yielded dict is filled on exit.

    Keys: ``launched`` (JIT kernels), ``new`` (not in Dr.Jit's in-memory cache: compiled, or read
    from its on-disk one, ``~/.drjit``), ``compiled`` (in neither), all over the process's threads
    (a JAX callback may render on one of XLA's), and ``compile_s`` (wall time of code generation
    and compilation of this thread's kernels: Dr.Jit's kernel history is per thread, s). A kernel
    recompiled at every call of a loop shows as ``new`` growing with the calls (``compiled`` too
    while the disk cache lacks it).
    """
    stats: dict[str, float] = {}
    dr.kernel_history_clear()
    launched, read, compiled = dr.detail.launch_stats()  # since the process started: launches, disk-cache reads, compilations
    with dr.scoped_set_flag(dr.JitFlag.KernelHistory, True):
        try:
            yield stats
        finally:
            jit = [k for k in dr.kernel_history() if k["type"] == dr.KernelType.JIT]
            now = dr.detail.launch_stats()
            stats.update(launched=now[0] - launched, new=now[1] - read + now[2] - compiled, compiled=now[2] - compiled,
                         compile_s=sum(k.get("codegen_time", 0.0) + k.get("backend_time", 0.0) for k in jit) / 1e3)


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
        ``deterministic`` (:func:`render_threads`), in the samples' order: the image is the one a
        render wholly on one thread gives, bit for bit, in 0.54 to 0.62x its time on 2 cores."""
        camera, _ = self.frozen.functions(self.geometry)
        position, rgb = camera(self.scene, self._pixels, mi.UInt32(seed), spp, start, count, self.window[2])
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


def differentiable(value: object) -> bool:
    """Whether AD differentiates a scene value: a frame (the sun's, the camera's) is set whole, its
    Jacobian columns come from finite differences."""
    return not isinstance(value, mi.AffineTransform4f)


def to_value(template: object, value: np.ndarray) -> object:
    """A Dr.Jit value of the type of ``template`` (a scene parameter) from a float array, opaque
    (evaluated, not a literal): the frozen passes (:mod:`spacefit.rendering.frozen`) take it as an
    operand and replay, where a literal would be compiled into their kernels and retraced at each change.

    A transform is given whole (16 numbers, the camera's :meth:`~spacefit.geometry.frames.CameraFrame.mitsuba_to_world`)
    or, for a distant light's frame, by the direction its +z axis points along (3 numbers).
    """
    value = np.asarray(value, dtype=np.float32).ravel()
    if isinstance(template, mi.AffineTransform4f) and value.size == 16:
        result = mi.AffineTransform4f(value.reshape(4, 4))
    elif isinstance(template, mi.AffineTransform4f):
        d = value / np.linalg.norm(value)
        up = [0.0, 1.0, 0.0] if abs(d[1]) < 0.9 else [1.0, 0.0, 0.0]
        result = mi.AffineTransform4f(mi.ScalarTransform4f().look_at(origin=[0, 0, 0], target=d.tolist(), up=up))
    elif isinstance(template, mi.Color3f):
        result = mi.Color3f(*(mi.Float(value[i % len(value)]) for i in range(3)))
    else:
        result = type(template)(value)
    dr.make_opaque(result)
    return result
