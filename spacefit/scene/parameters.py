"""The registry of free parameters, as data: one home for every fittable (and sweepable) scene value.

Each :class:`~spacefit.scene.entries.Parameter` is one entry of :data:`PARAMETERS` carrying everything about it: its name
pattern, unit, valid range (:class:`~spacefit.scene.entries.Bounds`), how to read its value from a scene and which
scene-file keys it sets (its getter and setter), its groups (:data:`GROUPS`: moves vertices, a
nuisance, image-space, one per observation, set jointly with others), its finite-difference step
(or 0 for forward-mode AD), the scene-file fields it replaces and, for materials, the models that
have it. The entries themselves are :mod:`spacefit.scene.registered`'s; the material entries are
the registered models', so :data:`PARAMETERS` reads them live. The group tuples (:data:`GEOMETRY`, :data:`ATTITUDE`, :data:`NUISANCES`, ...) are
derived from the entries, so a new parameter is added in one place. The CLI's help, the error
messages and the documentation's table (:func:`parameter_table`) are generated from it. Here too are
a name's entry and words (:func:`parameter`, :func:`label`, :func:`check_value`, :func:`scene_keys`) and a
scene's names and values (:func:`available`, :func:`check_names`, :func:`scene_value`,
:func:`scene_with_values`). The module is plain Python and NumPy: the solver's coordinates on these
ranges (bijections, in JAX) are the fitting code's, :mod:`spacefit.fitting.params`.

Names address the scene file's keys: ``wrinkles.D``; ``parts.P.alpha_x`` for part ``P``;
``sun.elevation_deg``. ``image.*`` are fit-only names (a render or a sweep refuses them). Together
with the target's pose (``target.attitude_*_deg``, ``target.position_*_m``) and the camera's roll
about its optical axis (``camera.roll_deg``) they are a fit's nuisance parameters
(:data:`NUISANCES`), reported apart from the materials. Each nuisance may be one per observation
of a joint fit (:data:`PER_OBSERVATION`): ``image.scale@k`` or ``target.attitude_z_deg@k`` is
observation k's alone (k from 0, in the order the observations are given; the others keep the
shared or their scene's value), ``image.scale`` one shared by all (:class:`spacefit.scene.names.Name`).
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any

from spacefit.errors import InputError, check_choice, check_name_list, check_range
from spacefit.materials import Material
from spacefit.materials.registry import Derived
from spacefit.scene.names import MARK, Name
from spacefit.scene.entries import GROUPS, Parameter
from spacefit.scene.registered import all_entries
from spacefit.scene.sections import SceneLike, check_scene, unknown_part

# Read live: the material entries are the registered models' (:func:`~spacefit.scene.registered.all_entries`).
#: The registry of free parameters: each name pattern (``parts.P.alpha_x`` stands for every part P
#: whose material has it) to its :class:`Parameter`: unit, valid range, how it is read from and set
#: in a scene, its finite-difference step. :func:`available_parameters` lists a scene's names,
#: :func:`parameter_table` the whole registry.
#:
#: Example:
#:     >>> import spacefit as sf
#:     >>> p = sf.PARAMETERS["wrinkles.G"]
#:     >>> p.unit, p.bounds.lo
#:     ('m', 0.0)
PARAMETERS: Mapping[str, Parameter] = Derived(lambda: {p.pattern: p for p in all_entries()})


def group(name: str) -> tuple[str, ...]:
    """The parameters of group ``name`` (:data:`GROUPS`), in registry order."""
    check_choice("group", name, GROUPS)
    return tuple(p.pattern for p in PARAMETERS.values() if name in p.groups)


GEOMETRY = group("wrinkles")
SUN_ANGLES = group("sun-angles")
ATTITUDE = group("attitude")
POSITION = group("position")
(ROLL,) = group("roll")
MOVES_VERTICES = group("moves-vertices")
IMAGE = group("image")
NUISANCES = group("nuisance")
PER_OBSERVATION = group("per-observation")
def is_image(name: str) -> bool:
    """Whether ``name`` is a fit-only image nuisance (:data:`IMAGE`), shared or one observation's."""
    return Name(name).parameter in IMAGE


def is_nuisance(name: str) -> bool:
    """Whether ``name`` is a nuisance parameter (:data:`NUISANCES`), shared or one observation's."""
    return Name(name).parameter in NUISANCES


def _pattern(name: str) -> str:
    name = Name(name).parameter
    section, *rest = name.split(".")
    return f"parts.P.{rest[-1]}" if section == "parts" and len(rest) == 2 else name


def parameter(name: str) -> Parameter:
    """The registry entry of a parameter name (``parts.panels.alpha_x`` -> ``parts.P.alpha_x``)."""
    pattern = _pattern(name)
    if pattern not in PARAMETERS:
        check_choice("parameter", name, PARAMETERS)
    return PARAMETERS[pattern]


def label(name: str) -> str:
    """A parameter's name in words, without its unit, for axes and tables: ``parts.panels.kd`` ->
    "albedo kd of panels", ``image.scale@1`` -> "exposure scale, observation 1"."""
    ref = Name(name)
    base, k = ref.parameter, ref.observation
    section, *rest = base.split(".")
    words = f"{parameter(name).label} of {rest[0]}" if section == "parts" and len(rest) == 2 else parameter(name).label
    return words if k is None else f"{words}, observation {k}"


def check_value(name: str, value: float, argument: str | None = None) -> float:
    """``value`` as a float if it is a valid value of parameter ``name`` (finite, within its bounds,
    which a scene value may reach), else :class:`InputError` naming ``argument`` (default: ``name``),
    the value and the range: the one check every entry point runs."""
    p = parameter(name)
    return check_range(argument or name, value, p.bounds.lo, p.bounds.hi, unit="" if p.unit == "1" else p.unit)


def scene_keys(name: str) -> set[str]:
    """The scene-file keys whose values parameter ``name`` replaces."""
    base = Name(name).parameter
    head = base.rsplit(".", 1)[0]
    return {f"{head}.{f}" for f in parameter(name).scene_fields} or {base}


def _joint() -> tuple[tuple[str, ...], ...]:
    """The "joint" parameters grouped by the scene value they set together."""
    by_key: dict[frozenset[str], tuple[str, ...]] = {}
    for name in group("joint"):
        by_key[frozenset(scene_keys(name))] = (*by_key.get(frozenset(scene_keys(name)), ()), name)
    return tuple(by_key.values())


# Parameters that set one scene value together.
JOINT = _joint()


def _materials(scene: SceneLike) -> dict[str, Material]:
    return {part: spec.material for part, spec in scene.parts.items()}


def available(scene: SceneLike) -> list[str]:
    """Every parameter name that can be freed (or swept) in ``scene``, in registry order.

    A part's parameters are named per part (``parts.panels.alpha_x``) and only for the parts whose
    material has them; the wrinkles' only where the scene has wrinkles. Each name's unit and valid
    range are in :data:`PARAMETERS` and :func:`parameter_table`.

    Args:
        scene: the scene (:class:`Scene`).

    Returns:
        The names, as ``sf.fit(free=...)``, ``sf.jacobian`` and ``sf.sweep`` take them.

    Raises:
        InputError: ``scene`` is not a :class:`Scene`.

    Example:
        >>> import spacefit as sf
        >>> names = sf.available_parameters(sf.default_scene())
        >>> names[:4]
        ['wrinkles.D', 'wrinkles.G', 'wrinkles.rms_m', 'parts.body.eta']
        >>> "parts.legs.kd" in names
        True
    """
    materials = _materials(check_scene(scene))
    names = []
    for p in PARAMETERS.values():
        if p.pattern.startswith("parts."):
            names += [p.pattern.replace(".P.", f".{part}.") for part, m in materials.items() if p.applies_to(m)]
        elif "wrinkles" not in p.groups or scene.wrinkles.enabled:
            names.append(p.pattern)
    return names


def _check_observation(argument: str, name: str, observations: int) -> None:
    """Raise :class:`InputError` unless ``name`` is a per-observation name (``image.scale@k``) with k in range."""
    base, _, index = name.partition(MARK)  # the user's text, as given: its index may be no number
    if base not in PER_OBSERVATION:
        raise InputError(f"`{argument}` names {name!r}, but only {', '.join(PER_OBSERVATION)} may be one observation's "
                         f"(`{PER_OBSERVATION[0]}{MARK}k`).")
    if index not in [str(k) for k in range(observations)]:
        raise InputError(f"`{argument}` names {name!r}: the observation index {index!r} must be an integer from 0 to "
                         f"{observations - 1} (the fit has {observations} observation{'s' * (observations > 1)}).")


def check_names(
    scene: SceneLike, names: Sequence[str], argument: str = "free", image: bool = False, observations: int = 1,
) -> tuple[str, ...]:
    """Return ``names`` as a tuple; raise :class:`InputError` for anything but a list of names, an
    unknown or repeated name, or two names that set the same value;
    ``image``: whether the names are a fit's (the fit-only :data:`IMAGE` nuisances and the
    per-observation forms are valid); ``observations``: how many observations a fit has (the range
    of a per-observation name's index, ``image.scale@k``)."""
    names = check_name_list(argument, names)
    valid = [n for n in available(scene) if image or n not in IMAGE]
    if not names:
        raise InputError(f"`{argument}` must name at least one parameter; valid: {', '.join(valid)}.")
    for name in names:
        forms = [n for n in valid if name not in valid and n not in IMAGE and name in scene_keys(n)]
        if MARK in name and image:
            _check_observation(argument, name, observations)
        elif name.count(".") == 2 and name.startswith("parts.") and name.split(".")[1] not in scene.parts:
            raise unknown_part(name, list(scene.parts))
        elif forms:
            raise InputError(f"`{argument}` names the scene-file key `{name}`, which holds several numbers; a parameter is "
                             f"one number: give {', '.join(f'`{n}`' for n in forms)}.")
        else:
            check_choice(argument, name, valid)
    refs = [Name(n) for n in names]
    for ref in refs:
        if ref.observation is not None and ref.parameter in names:
            raise InputError(f"`{argument}` names both {ref.parameter!r} (one for every observation) and {str(ref)!r} (observation "
                             f"{ref.observation}'s own); free one of the two forms.")
    if len(set(names)) != len(names):
        raise InputError(f"`{argument}` names a parameter twice: {list(names)}.")
    for a in refs:
        for b in refs:
            shared = a.observation is None or b.observation is None or a.observation == b.observation
            if (a < b and a.parameter != b.parameter and shared and scene_keys(a) & scene_keys(b)
                    and not any({a.parameter, b.parameter} <= set(g) for g in JOINT)):
                raise InputError(f"`{a}` and `{b}` set the same scene value; free one of them.")
    return tuple(refs)


def scene_value(scene: SceneLike, name: str) -> float:
    """The value of parameter ``name`` in the scene (its fixed value, or a fit's default start)."""
    name = Name(name).parameter
    return float(parameter(name).get(scene, name))


def fd_step(scene: SceneLike, name: str) -> float:
    """The central finite-difference step of ``name`` at the scene's value (0: forward-mode AD)."""
    p = parameter(name)
    return p.fd_step * (scene_value(scene, name) if p.relative_step else 1.0)


def parameter_table() -> str:
    """The registry of free parameters (:data:`PARAMETERS`) as a Markdown table: each pattern's unit,
    valid range, how its Jacobian column is computed and what it sets. The documentation's list of
    free parameters is this text, written at build time.

    Returns:
        The table, one row per registry entry, rows joined by newlines.

    Example:
        >>> import spacefit as sf
        >>> print(sf.parameter_table().splitlines()[2])
        | `wrinkles.D` | 1 | (2, 3) | central differences, step 0.02 1 | W-M fractal dimension (eq. 2-1): vertex positions of every wrinkled part |
    """
    rows = ["| name | unit | valid range | Jacobian column | sets |", "|---|---|---|---|---|"]
    for p in PARAMETERS.values():
        column = "forward-mode AD" if not p.fd_step else (
            f"central differences, step {p.fd_step:g}{' x value' if p.relative_step else ' ' + p.unit}")
        kinds = f" ({', '.join(m.__name__ for m in p.materials)})" if p.materials else ""
        own = f"; `{p.pattern}{MARK}k`: observation k's own" if "per-observation" in p.groups else ""
        rows.append(f"| `{p.pattern}` | {p.unit} | {p.bounds.describe()} | {column} | {p.doc}{kinds}{own} |")
    return "\n".join(rows)


def scene_with_values(scene: SceneLike, values: Mapping[str, float], observation: int | None = None) -> SceneLike:
    """A validated copy of ``scene`` with registered parameters set by name (physical units; the
    inverse of :func:`scene_value`): the scene file that renders them. Each entry's setter gives
    the keys: the sun's angles become ``sun.direction``, the pose's components set
    ``target.attitude_deg`` / ``position_m``, the rms height a G at the scene's (or the given) D, a
    conductor's ``alpha`` both its roughnesses. Each value is checked (:func:`check_value`). The fit-only :data:`IMAGE` nuisances are not scene values and are left out.
    ``observation``: the scene is a joint fit's observation k: its own per-observation values
    (``target.attitude_z_deg@k``) are set, and other observations' left out.

    Raises:
        InputError: for a name the scene cannot free, or a value out of its range.
    """
    v: dict[str, Any] = {}
    for name, x in values.items():
        ref = Name(name)
        if observation is not None and ref.observation is not None:
            if ref.observation == observation:
                v[ref.parameter] = x
        else:
            v[name] = x
    in_scene = [n for n in v if not is_image(n)]
    if in_scene:  # a fit of image nuisances alone renders its scene as given
        check_names(scene, in_scene, "values")
    v = {n: check_value(n, x) for n, x in v.items()}
    keys: dict[str, Any] = {}
    for name in v:
        keys.update(parameter(name).set(scene, name, v))
    return scene.with_values(keys)
