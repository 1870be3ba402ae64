"""A fitted value's name as one structured reference: the registered parameter and, for a value that one
observation (one frame of a pass) has alone, that observation.

A :class:`Name` is a ``str`` whose text is how a user writes it and how a fit's files hold it
(``target.attitude_x_deg`` shared by every observation, ``target.attitude_x_deg@2`` observation 2's
own; observations counted from 0 in the order a fit is given them), so that it keys the same
dictionaries as the text and writes itself into JSON and CSV as the text. That text is read here
once, by the constructor; code reads :attr:`Name.parameter` and :attr:`Name.observation`.
"""

from __future__ import annotations

from typing import Any

# Joins a per-observation parameter's name and its observation's index in the text: ``image.scale@1``.
MARK = "@"


class Name(str):
    """A parameter name with the observation it belongs to (None: shared by every observation).

    ``Name("image.scale@1")`` and ``Name("image.scale", 1)`` are the same name, equal to the text
    ``"image.scale@1"``. A text whose mark is not followed by a whole number is kept whole as the
    parameter (the registry then refuses it by name)."""

    parameter: str
    observation: int | None

    def __new__(cls, name: str, observation: int | None = None) -> Name:
        if isinstance(name, Name):
            if observation is None or observation == name.observation:
                return name
            name = name.parameter
        elif observation is None:
            base, mark, index = str(name).partition(MARK)
            if mark and index.isascii() and index.isdigit():
                name, observation = base, int(index)
        text = name if observation is None else f"{name}{MARK}{observation}"
        self = super().__new__(cls, text)
        self.parameter, self.observation = str(name), observation
        return self

    def __reduce__(self) -> tuple[Any, ...]:
        return Name, (self.parameter, self.observation)

    def shared(self) -> Name:
        """The same parameter, shared by every observation."""
        return Name(self.parameter)
