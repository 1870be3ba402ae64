"""``ObservationFiles``: how a fit's reference image files and scene files are read into
:class:`Observation`s (``spacefit fit``'s file options as one value)."""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from spacefit.errors import InputError, check_choice, check_name_list, check_path, check_range, check_type
from spacefit.fitting.problem import Observation
from spacefit.imageio import RESPONSES, ROW_ORDERS, SENSOR_DEFAULTS, UNITS
from spacefit.scene.schema import Scene
from spacefit.scene.toml import load_scene
from spacefit.units import RADIANCE_UNIT


@dataclass(frozen=True)
class ObservationFiles:
    """Reference image files and the scene files they were taken in, and how to read them; checked
    on construction (the files themselves by :meth:`load`). ``references``, ``scenes``, ``masks`` and
    ``overrides`` are kept as tuples; one file (or override) may be given as itself.

    Attributes:
        references: reference images, fitted jointly, read by :meth:`Observation.from_file`: radiance (EXR, FITS with a radiance
            ``BUNIT``), or DN (FITS, 16-bit PNG / TIFF) fitted with their sensor's noise model.
        scenes: scene TOML files: one for all references, or one per reference in order.
        overrides: ``key=value`` scene overrides applied to every scene.
        resolution: (width, height) px replacing every scene's ``render.resolution``; the
            references must have that size.
        sigma: noise standard deviation of radiance references, W m^-2 sr^-1 (residuals are divided by it).
        masks: mask images (FITS, PNG, TIFF; 0 = leave the pixel out, 1 or full scale = use it): none, one for all
            references, or one per reference in order; saturated pixels are left out in any case.
        sensor_file: a JSON or TOML file of :class:`Sensor` fields
            (:func:`read_sensor_file`) for DN references: they replace the
            fields of each file's own sensor (FITS header or sidecar), or describe the camera of a
            file that names none.
        sensor_values: sensor fields replacing the file's and the sensor file's.
        sensor_defaults: ``"illustrative"`` to fill missing sensor values with the illustrative defaults.
        row_order: ``"top-down"`` / ``"bottom-up"``: how FITS rows run, whatever the files say.
        flat: a flat-field image (FITS, PNG, TIFF) of the DN references' detector, for all of them.
        unit: ``"radiance"`` / ``"DN"`` to require one (:func:`read_image`).
        response: ``"linear"`` / ``"srgb"`` for PNG and TIFF.
        values: per reference, scene values (by name, as ``overrides``) set on its scene after
            ``overrides``: a pass's frames (:class:`Pass`); none, or one per reference.
        frame_sensor_values: per reference, sensor fields replacing ``sensor_values``' (none, or one per reference).
        times: per reference, its time (ISO 8601 UTC, or seconds), recorded; none, or one per reference.

    Raises:
        InputError: counts that do not match (one scene for all references or one each), an
            unknown option value.

    Example:
        >>> import spacefit as sf
        >>> files = sf.ObservationFiles(references=["ref.exr"], scenes=["lander.toml"], sigma=0.01)
        >>> files.references  # files.load() reads them into sf.Observation objects
        ('ref.exr',)
    """

    references: Sequence[str | Path]
    scenes: Sequence[str | Path]
    overrides: Sequence[str] = ()
    resolution: tuple[int, int] | None = None
    sigma: float | None = None
    masks: Sequence[str | Path] = ()
    sensor_file: str | Path | None = None
    sensor_values: Mapping[str, Any] | None = None
    sensor_defaults: str | None = None
    row_order: str | None = None
    flat: str | Path | None = None
    unit: str | None = None
    response: str | None = None
    values: Sequence[Mapping[str, Any]] = ()
    frame_sensor_values: Sequence[Mapping[str, Any]] = ()
    times: Sequence[str] = ()

    def __post_init__(self) -> None:
        for name in ("references", "scenes", "masks", "overrides"):  # one file (or override) may be given as itself
            given = getattr(self, name)
            items = (given,) if isinstance(given, (str, Path)) else check_name_list(name, given) if name == "overrides" else given
            check_type(name, items, Sequence, "a path or a list of paths")
            for i, path in enumerate(items if name != "overrides" else ()):
                check_path(f"{name}[{i}]", path)
            object.__setattr__(self, name, tuple(items))
        for name, kind, what in (("values", Mapping, "a table of scene values"), ("frame_sensor_values", Mapping, "a table of sensor fields"),
                                 ("times", str, "a time (ISO 8601 text)")):  # one entry per reference
            given = getattr(self, name)
            check_type(name, given, Sequence, f"a list with one entry per reference, each {what}")
            for i, entry in enumerate(given):
                check_type(f"{name}[{i}]", entry, kind, what)
            object.__setattr__(self, name, tuple(given))
        n = len(self.references)
        if not n:
            raise InputError("`references` must name at least one reference image.")
        for what, given, counts in (("scene", self.scenes, (1, n)), ("mask", self.masks, (0, 1, n))):
            if len(given) not in counts:
                raise InputError(f"give one {what} for all references or one per reference; "
                                 f"got {len(given)} {what}s for {n} references.")
        for what, given in (("values", self.values), ("frame_sensor_values", self.frame_sensor_values), ("times", self.times)):
            if len(given) not in (0, n):
                raise InputError(f"`{what}` must give one entry per reference or none; got {len(given)} for {n} references.")
        if self.resolution is not None:  # its range is the scene's `render.resolution`'s, checked by `load`
            if not isinstance(self.resolution, Sequence) or len(self.resolution) != 2:
                raise InputError(f"`resolution` must be (width, height) px, got {self.resolution!r}.")
            object.__setattr__(self, "resolution", tuple(self.resolution))
        if self.sigma is not None:
            check_range("sigma", self.sigma, 0.0, lo_open=True, unit=RADIANCE_UNIT)
        for name, value, choices in (("sensor_defaults", self.sensor_defaults, SENSOR_DEFAULTS),
                                     ("row_order", self.row_order, ROW_ORDERS), ("unit", self.unit, UNITS),
                                     ("response", self.response, RESPONSES)):
            if value is not None:
                check_choice(name, value, choices)

    @property
    def files(self) -> tuple[str | Path, ...]:
        """Every input file named (no output may write over one)."""
        return (*self.references, *self.scenes, *self.masks, *(p for p in (self.sensor_file, self.flat) if p is not None))

    @property
    def scene_overrides(self) -> list[str]:
        """The overrides applied to every scene, ``resolution`` as the last."""
        w_h = [f"render.resolution=[{self.resolution[0]}, {self.resolution[1]}]"] if self.resolution else []
        return [*self.overrides, *w_h]

    def load(self) -> list[Observation]:
        """Read the scenes and the references, one observation per reference.

        Raises:
            InputError: for a scene or an image file refused (:func:`load_scene`,
                :meth:`Observation.from_file`).
        """
        loaded = [load_scene(path, self.scene_overrides) for path in self.scenes]
        return [Observation.from_file(path, self._scene(loaded[i % len(loaded)], i), sensor=self._sensor_values(i),
                                      sensor_file=self.sensor_file,
                                      unit=self.unit, response=self.response,
                                      mask=self.masks[i % len(self.masks)] if self.masks else None, sigma=self.sigma,
                                      sensor_defaults=self.sensor_defaults, row_order=self.row_order, flat=self.flat)
                for i, path in enumerate(self.references)]

    def _scene(self, scene: Scene, i: int) -> Scene:
        """Reference i's scene: ``scene`` with its own ``values`` (the frame named in a refusal)."""
        if not self.values or not self.values[i]:
            return scene
        try:
            return scene.with_values(dict(self.values[i]))
        except InputError as err:
            raise type(err)(f"reference {i} ({Path(self.references[i]).name}): {err}") from None

    def _sensor_values(self, i: int) -> Mapping[str, Any] | None:
        """Reference i's sensor values: ``sensor_values`` with its own ``frame_sensor_values``."""
        own = self.frame_sensor_values[i] if self.frame_sensor_values else {}
        return {**(self.sensor_values or {}), **own} or self.sensor_values

    def record(self, observations: Sequence[Observation]) -> dict[str, Any]:
        """What fit.json's ``inputs`` record of these files, given the observations :meth:`load` read."""
        return {
            "references": [str(path) for path in self.references],
            "scene_files": [str(path) for path in self.scenes],
            "overrides": self.scene_overrides,
            "scenes": [obs.scene.to_dict() for obs in observations[:max(len(self.scenes), len(self.values))]],
            "values": [dict(v) for v in self.values],
            "frame_sensor_values": [dict(v) for v in self.frame_sensor_values],
            "times": list(self.times),
            "sigma": self.sigma,
            "masks": [str(path) for path in self.masks],
            "sensor_file": None if self.sensor_file is None else str(self.sensor_file),
            "sensors": [None if obs.sensor is None else obs.sensor.to_dict() for obs in observations],
            "sensor_sources": [obs.sensor_sources for obs in observations],
            "notes": [list(obs.notes) for obs in observations],
            "flat": None if self.flat is None else str(self.flat),
            "unit": self.unit,
            "response": self.response,
        }
