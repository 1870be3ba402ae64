"""The checkpoint plumbing of a fit, as one value: what :func:`fit` reports of each step and of
its end, and what it takes back to end or go on as an interrupted or killed fit would have
(:func:`fit_to_folder`'s checkpoint and ``--resume``)."""

from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from typing import Any


@dataclass(frozen=True)
class Resume:
    """How a fit checkpoints and resumes (the default: it does neither).

    Attributes:
        on_step: called with each step's history entry (step, loss, values, time_s), e.g. to
            checkpoint the best point so far.
        on_end: called once the solve has ended (not when interrupted), before the errors and renders
            are computed, with the record that ``ended`` takes: its status, steps, end values and history.
        ended: such a record, of a solve that ended before its process was killed: the solve is not
            run again; the fit's ``start`` must be the record's values. The result is the one the ended
            fit would have given: same status, steps, values and verdict.
        history: the history of an interrupted solve (its steps' entries, as ``on_step`` had them), whose
            best point is the fit's ``start``: the solve goes on from there, its steps counted after
            them, and what the stop rule (``sf.fit(stop=...)``) and the verdict know of them
            kept, so that it ends as the uninterrupted one would (``--resume``).

    Example:
        Keep each step's values, as a checkpoint would:

        >>> import spacefit as sf
        >>> steps = []
        >>> resume = sf.Resume(on_step=steps.append)  # sf.fit(..., resume=resume)
        >>> resume.ended is None
        True
    """

    on_step: Callable[[dict[str, Any]], None] | None = None
    on_end: Callable[[dict[str, Any]], None] | None = None
    ended: Mapping[str, Any] | None = None
    history: Sequence[Mapping[str, Any]] = ()
