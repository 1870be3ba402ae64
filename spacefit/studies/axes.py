"""A sweep's axes: the swept scene keys and their values, checked against the scene.

An axis is one key's list of values, or several keys' lists of equal length zipped under the axis's
name; a list may be spelled ``{"linspace": [start, stop, num]}`` or ``{"arange": [start, stop, step]}``
(the spelling: :mod:`spacefit.studies.sweep`). Each key's unit is the parameter registry's, else its
suffix's; the registered parameters but the wrinkles' D, G and rms height are set on the loaded scene
(:func:`in_place_names`), other keys assemble it again.
"""

from __future__ import annotations

import json
import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from spacefit.errors import InputError, InputTypeError, check_count, check_range, closest, quote
from spacefit.scene.parameters import GEOMETRY, SUN_ANGLES, available, parameter
from spacefit.scene.schema import Scene
from spacefit.scene.sections import sun_followers

# Scene keys a sweep cannot vary: they fix the shape of the store's images and part lists.
FIXED_KEYS = ("render.resolution", "target.mesh")
SUFFIX_UNITS = {"_m": "m", "_mm": "mm", "_deg": "deg", "_w_m2": "W m^-2", "_px": "px"}
AxesSpec = Mapping[str, Any]


@dataclass(frozen=True)
class Axis:
    """One dimension of a sweep: its name and the values of each key along it (equal lengths)."""

    name: str
    values: dict[str, list[Any]]

    @property
    def size(self) -> int:
        """Number of points along the axis."""
        return len(next(iter(self.values.values())))


def units(key: str) -> str:
    """The unit of a swept key: the registry's for a parameter, else from the key's suffix ("1" if none)."""
    try:
        return parameter(key).unit
    except InputError:
        return _suffix_unit(key)


def _suffix_unit(key: str) -> str:
    return next((u for suffix, u in SUFFIX_UNITS.items() if key.endswith(suffix)), "1")


def _values(key: str, spec: Any) -> list[Any]:
    """A key's list of values from a list or a ``linspace`` / ``arange`` table."""
    if isinstance(spec, Mapping):
        rule = next(iter(spec)) if len(spec) == 1 else None
        if rule == "linspace" and isinstance(spec[rule], list) and len(spec[rule]) == 3:
            start, stop, num = spec["linspace"]
            check_count(f"axes[{key!r}].linspace num", num)
            values = np.linspace(check_range(f"axes[{key!r}].linspace start", start),
                                 check_range(f"axes[{key!r}].linspace stop", stop), int(num))
            whole = all(isinstance(v, int) and not isinstance(v, bool) for v in (start, stop))
            if whole and np.all(values == np.round(values)):  # integers stay integers (render.spp)
                return values.astype(int).tolist()
            return values.tolist()
        if rule == "arange" and isinstance(spec[rule], list) and len(spec[rule]) == 3:
            bounds = [check_range(f"axes[{key!r}].arange", v) for v in spec["arange"]]
            start, stop, step = bounds
            if not step or (stop - start) / step <= 0:
                raise InputError(f"`axes[{key!r}].arange` = {spec['arange']} gives no values; use [start, stop, step] "
                                 "with a step towards stop.")
            whole = all(isinstance(v, int) and not isinstance(v, bool) for v in spec["arange"])  # integers stay integers (render.seed)
            return np.arange(*(spec["arange"] if whole else bounds)).tolist()
        close = [c for c in (closest(str(k), ("linspace", "arange")) for k in spec) if c]
        hint = f" Did you mean {{{close[0]} = [start, stop, ...]}}?" if close else ""
        raise InputError(f"`axes[{key!r}]` must be a list of values, {{linspace = [start, stop, num]}} or "
                         f"{{arange = [start, stop, step]}}, got {quote(dict(spec))}.{hint}")
    if isinstance(spec, (str, bytes)) or not isinstance(spec, Sequence | np.ndarray) or len(spec) == 0:
        raise InputError(f"`axes[{key!r}]` must be a non-empty list of values, got {quote(spec)}.")
    try:
        return [np.asarray(v).tolist() for v in spec]
    except (TypeError, ValueError, RecursionError, OverflowError):  # a ragged value: [1, [2, 3]]
        raise InputError(f"`axes[{key!r}]` must be a list of values, each a number, a string or a list of numbers, "
                         f"got {quote(spec)}.") from None


def _zipped(spec: Any) -> bool:
    """Whether an axis zips several scene keys: a table whose keys are scene keys (they have dots;
    ``linspace`` and ``arange`` have none)."""
    return isinstance(spec, Mapping) and any("." in str(k) for k in spec)


def parse_axes(scene: Scene, axes: AxesSpec) -> list[Axis]:
    """Check a sweep's axes against the scene (every key and value) and return them in order."""
    if not isinstance(axes, Mapping) or not axes:
        raise InputTypeError(f"`axes` must be a non-empty mapping of scene keys to lists of values, got {quote(axes)}.")
    parsed = []
    for name, spec in axes.items():
        values = {k: _values(k, v) for k, v in spec.items()} if _zipped(spec) else {name: _values(name, spec)}
        if not values:
            raise InputError(f"axis {name!r} zips no keys: give it a table of scene keys and their lists of values.")
        if len({len(v) for v in values.values()}) > 1:
            raise InputError(f"the zipped keys of axis {name!r} must have lists of equal length, got "
                             f"{ {k: len(v) for k, v in values.items()} }.")
        parsed.append(Axis(name, values))
    keys = [k for a in parsed for k in a.values]
    if len(set(keys)) != len(keys):
        raise InputError(f"`axes` names a key twice: {keys}.")
    for axis in parsed:
        for key, vals in axis.values.items():
            if key in FIXED_KEYS:
                raise InputError(f"`axes` may not sweep {key!r}: it fixes the store's images and parts; run one sweep per value.")
            for v in dict.fromkeys(map(json.dumps, vals)):  # every distinct value, checked as the scene would
                value = json.loads(v)
                if isinstance(value, int) and not isinstance(value, bool) and not -(2**63) <= value < 2**63:
                    raise InputError(f"`axes[{key!r}]` holds {value}, an integer past 64 bits, which the store cannot hold: "
                                     "give it as a float.")
                try:
                    scene.with_values({key: value})
                except InputError as err:
                    raise type(err)(f"`axes[{key!r}]` holds {quote(value)}: {err}") from None
    return parsed


def in_place_names(scene: Scene) -> set[str]:
    """The registered parameters a sweep sets on the loaded scene: all but the wrinkles' D, G and rms
    height, whose points assemble the scene again (the refinement is kept, the displacement redone, and
    the level of detail's effective roughness follows them), and the sun's angles where parts or the
    body follow the sun (:func:`~spacefit.scene.sections.sun_followers`: they turn when assembled)."""
    return set(available(scene)) - set(GEOMETRY) - (set(SUN_ANGLES) if sun_followers(scene) else set())


def axis_lengths(axes: AxesSpec) -> list[int]:
    """The number of points along each axis, from the specification alone (no list of values built);
    0 for an axis that :func:`parse_axes` will refuse."""
    if not isinstance(axes, Mapping):
        return [0]

    def length(spec: Any) -> int:
        if isinstance(spec, Mapping) and set(spec) == {"linspace"} and isinstance(spec["linspace"], Sequence):
            num = spec["linspace"][2] if len(spec["linspace"]) == 3 else 0
            return num if isinstance(num, int) and not isinstance(num, bool) and num > 0 else 0
        if isinstance(spec, Mapping) and set(spec) == {"arange"} and isinstance(spec["arange"], Sequence):
            try:
                start, stop, step = (float(v) for v in spec["arange"])
                return max(0, math.ceil((stop - start) / step))
            except (TypeError, ValueError, ZeroDivisionError, OverflowError):
                return 0
        if _zipped(spec):  # its keys' lengths are checked equal later
            return max((length(v) for v in spec.values()), default=0)
        if isinstance(spec, Mapping):
            return 0
        return len(spec) if isinstance(spec, Sequence | np.ndarray) and not isinstance(spec, str | bytes) else 0

    return [length(spec) for spec in axes.values()]


def parsed_seeds(scene: Scene, axes: list[Axis]) -> list[int]:
    """The render seeds a sweep uses: the swept ``render.seed`` values, else the scene's."""
    swept = [v for a in axes for k, vals in a.values.items() if k == "render.seed" for v in vals]
    return [int(s) for s in swept] or [scene.render.seed]
