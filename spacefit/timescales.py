"""UTC times past the leap-second table, converted without ERFA's "dubious year" warnings.

astropy converts UTC through ERFA, which warns ``ErfaWarning: ... "dubious year"`` for every time after
the last date its leap-second table covers (IERS Bulletin C, about six months ahead) and for every
conversion of it: a pass fit of frames in 2030 printed it 56 times. For spacefit such times are
simulations or planned observations, and a leap second not yet announced moves a UTC time by at most
1 s (the sun by 0.004 deg): nothing the user can act on, so :func:`quiet_future_utc` says nothing of
it where spacefit converts times. The same holds for astropy's warning that polar motion past the
IERS table is its 50-year mean (arcseconds, against the 0.5 deg of the sun's disc). Other warnings
pass.
"""

from __future__ import annotations

import functools
import warnings
from collections.abc import Callable
from typing import ParamSpec, TypeVar

P = ParamSpec("P")
R = TypeVar("R")

# The texts of the warnings for times past the tables: ERFA's for UTC past the leap-second table (its
# message, whatever the function), astropy's for polar motion past the IERS table.
FUTURE_TIME_WARNINGS = (r".*dubious year", r"Tried to get polar motions for times after IERS data is valid")


def quiet_future_utc(fn: Callable[P, R]) -> Callable[P, R]:
    """Run ``fn`` with the warnings of :data:`FUTURE_TIME_WARNINGS` ignored (see the module's docstring)."""

    @functools.wraps(fn)
    def quiet(*args: P.args, **kwargs: P.kwargs) -> R:
        with warnings.catch_warnings():
            for message in FUTURE_TIME_WARNINGS:
                warnings.filterwarnings("ignore", message=message)
            return fn(*args, **kwargs)

    return quiet
