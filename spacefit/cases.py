"""Synthetic fitting cases with known truth: the one source for the tests, the experiments and
``data/synthetic/make_references.py``.

The cases are package data, ``spacefit/synthetic/`` (``cases.toml`` and the scene files it names),
found through :mod:`importlib.resources`, so an installed wheel has them (``pyproject.toml``'s
package-data). The references rendered from them (``reference.exr``, ...) are the generator's
output and stay with it in the repository's ``data/synthetic/NAME/``.
"""

from __future__ import annotations

import tomllib
from collections.abc import Mapping
from dataclasses import dataclass, field
from importlib.resources import as_file, files
from typing import Any

import numpy as np

from spacefit.errors import InputError, check_choice, check_range
from spacefit.scene.schema import Scene
from spacefit.scene.toml import load_scene
from spacefit.scene.parameters import check_names, scene_value

# The package-data folder of the cases (a Traversable: a folder, or a place in a zip).
CASES_DIR = files("spacefit") / "synthetic"


def add_noise(radiance: np.ndarray, percent: float, seed: int) -> tuple[np.ndarray, float]:
    """Radiance plus Gaussian noise of ``percent`` % of the lit pixels' mean radiance, independent per
    pixel and channel, drawn by ``numpy.random.default_rng([seed, percent])``; and that sigma
    (W m^-2 sr^-1). Values below zero are kept, so the noise stays zero-mean."""
    lit = radiance.max(axis=-1) > 0
    sigma = percent / 100.0 * float(radiance[lit].mean())
    noise = np.random.default_rng([seed, int(percent)]).normal(0.0, sigma, radiance.shape)
    return (radiance + noise).astype(np.float32), sigma


@dataclass(frozen=True)
class Case:
    """A synthetic case: the truth scene (its reference's), free parameters, start, fit settings.

    Attributes:
        name: the case's name in ``cases.toml``.
        truth_scene: the scene at the true values, rendered with the reference's samples and seed.
        free: the free parameters.
        start: where fits start (physical units).
        fit_values: scene values fits render with (e.g. fewer samples).

    Example:
        >>> import spacefit as sf
        >>> case = sf.load_case("default")
        >>> case.truth
        {'parts.panels.alpha_x': 0.08, 'parts.panels.alpha_y': 0.05, 'parts.legs.kd': 0.2}
        >>> case.start
        {'parts.panels.alpha_x': 0.04, 'parts.panels.alpha_y': 0.025, 'parts.legs.kd': 0.1}
    """

    name: str
    truth_scene: Scene
    free: tuple[str, ...]
    start: dict[str, float]
    fit_values: dict[str, Any] = field(default_factory=dict)

    @property
    def truth(self) -> dict[str, float]:
        """The true value of each free parameter."""
        return {n: scene_value(self.truth_scene, n) for n in self.free}

    def scene(self) -> Scene:
        """The scene a fit renders: the truth scene with :attr:`fit_values` (fits start at :attr:`start`)."""
        return self.truth_scene.with_values(self.fit_values)

    def reference(self, noise_percent: float = 0.0) -> tuple[np.ndarray, float | None]:
        """The reference radiance (W m^-2 sr^-1) rendered at the truth, with :func:`add_noise` of
        ``noise_percent`` % if given, and the noise's sigma (None without noise)."""
        from spacefit.rendering.renderer import render  # here: Mitsuba takes seconds to import; reading a case never renders

        check_range("noise_percent", noise_percent, 0.0, 100.0, unit="%")
        image = render(self.truth_scene)
        if not noise_percent:
            return image, None
        return add_noise(image, noise_percent, self.truth_scene.render.seed)

    def with_values(self, values: Mapping[str, Any], name: str | None = None) -> Case:
        """The same case with more scene values (another view, range or size) for truth and fits."""
        return Case(name or self.name, self.truth_scene.with_values(values), self.free, self.start,
                    {k: v for k, v in self.fit_values.items() if k not in values})


def case_names() -> list[str]:
    """The names of the synthetic cases :func:`load_case` loads (package data, in the order of its cases file).

    Returns:
        The case names.

    Example:
        >>> import spacefit as sf
        >>> sf.case_names()
        ['default', 'panels', 'materials', 'wrinkles', 'wrinkles_128', 'wrinkles_far']
    """
    return list(_table())


def _table() -> dict[str, Any]:
    path = CASES_DIR / "cases.toml"
    if not path.is_file():
        raise InputError(f"the synthetic cases are missing from this installation of spacefit ({path}): reinstall it "
                         "from a wheel built with the package data of pyproject.toml.")
    return tomllib.loads(path.read_text())


def load_case(name: str) -> Case:
    """A synthetic fitting case with known truth: the scene its reference is rendered from, the
    parameters a fit frees and where it starts. The tests, the experiments and the documentation's
    examples share these cases.

    Args:
        name: one of :func:`case_names`.

    Returns:
        The :class:`Case`; ``case.reference()`` renders its reference image.

    Raises:
        InputError: ``name`` is not one of :func:`case_names`.

    Example:
        >>> import spacefit as sf
        >>> case = sf.load_case("default")
        >>> case.free
        ('parts.panels.alpha_x', 'parts.panels.alpha_y', 'parts.legs.kd')
        >>> case.truth_scene.render.resolution
        (128, 128)
    """
    table = _table()
    entry = table[check_choice("case", name, table)]
    with as_file(CASES_DIR / f"{entry.get('scene', name)}.toml") as path:
        scene = load_scene(path, entry.get("values", {}))
    free = tuple(entry["free"])
    check_names(scene, free)
    return Case(name, scene, free, {k: float(v) for k, v in entry["start"].items()}, dict(entry.get("fit", {})))
