"""The pass kind of observation: the frames of a pass (:class:`Pass`) with
each frame's image, fitted as one observation of :func:`fit`.

The fit's set-up (:func:`spacefit.fitting.problem.setup`) expands a :class:`PassObservation` into its
frames' images, in order, after the images given before it, and frees for each frame its own value
of each of :attr:`PassObservation.per_frame` (``target.attitude_x_deg`` -> the structured names
``Name("target.attitude_x_deg", k)`` of the frames' observation indices k,
:class:`~spacefit.scene.names.Name`). The fit is the same, bit for bit, as one of the frames' images
given as a list with those names free. Its report is its frame table (:func:`frame_table`),
its figure :func:`plot_frames`.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from spacefit.errors import InputError, InputTypeError, check_name_list, check_type, quote
from spacefit.fitting.observations.image import Observation
from spacefit.fitting.pass_report import frame_table, plot_frames
from spacefit.fitting.passes import Pass
from spacefit.fitting.result import FitResult
from spacefit.scene.names import Name
from spacefit.scene.schema import Scene
from spacefit.sensor import Sensor

if TYPE_CHECKING:  # types only: matplotlib loads where a figure is drawn
    from spacefit.plotting import AxesArg, FigureArg


@dataclass(frozen=True, eq=False)
class PassObservation:
    """A pass and its frames' images, one per frame in the pass's order.

    Attributes:
        frames: the pass (its frames' files, times and values).
        images: each frame's image and scene (:meth:`read` makes them from the frames' files).
        per_frame: the parameters each frame has its own value of (:meth:`Pass.per_frame`
            checks them), freed per frame by the fit.

    Example:
        >>> import spacefit as sf
        >>> scene = sf.default_scene().with_values({"render.resolution": [48, 48], "camera.pixel_pitch_mm": 50, "render.spp": 4})
        >>> _ = sf.simulate_pass(scene, sf.arc_pass(2), "pass", spp=4)
        >>> observation = sf.PassObservation.read("pass/frames.csv", scene, per_frame=["target.attitude_x_deg"])
        >>> type(observation).__name__  # sf.fit([observation], free) frees each frame's attitude too
        'PassObservation'
    """

    frames: Pass
    images: Sequence[Observation]
    per_frame: Sequence[str] = ()

    def __post_init__(self) -> None:
        check_type("frames", self.frames, Pass, "an sf.Pass (sf.Pass.read a frame table)")
        if isinstance(self.images, (str, bytes)) or not isinstance(self.images, Sequence):
            raise InputTypeError(f"`images` must be a list of sf.Observation, one per frame, got {quote(self.images)}.")
        object.__setattr__(self, "images", tuple(self.images))
        for i, image in enumerate(self.images):
            check_type(f"images[{i}]", image, Observation, "an sf.Observation(scene, reference)")
        if len(self.images) != len(self.frames):
            raise InputError(f"the pass has {len(self.frames)} frames but {len(self.images)} images are given: give one per frame.")
        object.__setattr__(self, "per_frame", tuple(check_name_list("per_frame", list(self.per_frame))))
        self.frames.per_frame(self.per_frame)

    @classmethod
    def read(cls, frames: Pass | str | Path, scene: Scene, per_frame: Sequence[str] = (), **options: Any) -> PassObservation:
        """The pass ``frames`` (or the frame table file it is read from, :meth:`Pass.read`) with each frame's image read from its file in its scene
        (``scene`` with the frame's values) by :meth:`Observation.from_file`, which takes ``options``; a
        frame's mask and sensor values are the table's."""
        frames = frames if isinstance(frames, Pass) else Pass.read(frames)
        images = []
        for frame, frame_scene in zip(frames.frames, frames.scenes(scene)):
            own = dict(options)
            if frame.mask is not None:
                own["mask"] = frame.mask
            if frame.sensor:
                given = options.get("sensor")
                own["sensor"] = (dataclasses.replace(given, **frame.sensor) if isinstance(given, Sensor)
                                 else {**(given or {}), **frame.sensor})
            images.append(Observation.from_file(frame.file, frame_scene, **own))
        return cls(frames, images, per_frame)

    def names(self, first: int) -> list[Name]:
        """The per-frame free names of the frames when the first is the fit's observation ``first``."""
        return [Name(name, first + k) for name in self.per_frame for k in range(len(self.frames))]

    def report(self, result: FitResult, entries: Sequence[int]) -> list[str]:
        """One line per frame (:func:`frame_table`): its time, its
        chi^2 / dof and its own values with their standard errors."""
        lines = [f"  pass of {len(self.frames)} frames (observations {entries[0]} to {entries[-1]}):"]
        for row in frame_table(result, self.frames, entries=entries):
            chi2 = row.get("chi2_dof", math.nan)
            own = ", ".join(f"{name} = {row[name]:.6g} +/- {row[f'{name}.stderr']:.3g}" for name in self.per_frame if name in row)
            misfit = " (a MISFIT on its own)" if row.get("misfit") else ""
            lines.append(f"    frame {row['frame']} at {row['time_s']:.6g} s: chi^2/dof {chi2:.3g}{misfit}" + (f"; {own}" if own else ""))
        return lines

    def plot(self, result: FitResult, entries: Sequence[int], *, ax: AxesArg = None, fig: FigureArg = None) -> np.ndarray:
        """Its frames' own values and chi^2 / dof against time (:func:`plot_frames`)."""
        return plot_frames(frame_table(result, self.frames, entries=entries), ax=ax, fig=fig)
