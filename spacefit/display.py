"""How results show in Jupyter (``_repr_html_``): HTML tables of the same cells as the text tables, every value
with its unit and error, escaped, in the parameter registry's words.

The classes' ``_repr_html_`` methods call these (:class:`~spacefit.fitting.result.FitResult`,
:class:`~spacefit.studies.sensitivity.Sensitivity`, :class:`~spacefit.studies.lightcurve.LightCurve`), which sit
above it: each function reads its object by attribute (typed ``Any``) and imports none of them; nothing here imports
more than the parameter registry. A :class:`~spacefit.scene.schema.Scene`, below the registry's words, shows itself.
"""

from __future__ import annotations

import html
from collections.abc import Mapping
from typing import Any

from spacefit.errors import InputError
from spacefit.html_tables import html_table
from spacefit.scene.parameters import label, parameter

# A value's unit where it is dimensionless, in tables: none.
DIMENSIONLESS = "1"
# What is not a registered parameter but may be swept or plotted: name -> (words, unit).
QUANTITIES = {"phase_angle_deg": ("solar phase angle", "deg"), "time_s": ("time", "s")}


def describe(name: str) -> tuple[str, str]:
    """The words and unit of a parameter (:func:`spacefit.scene.parameters.label`) or one of :data:`QUANTITIES`."""
    return QUANTITIES[name] if name in QUANTITIES else (label(name), parameter(name).unit)


def unit_text(unit: str) -> str:
    """A unit as a table shows it: "" for a dimensionless one."""
    return "" if unit == DIMENSIONLESS else unit


def fit_html(result: Any) -> str:
    """The verdict, the goodness of fit, each fitted value with its standard error, unit and start,
    the derived values, and the warnings."""
    lines = [result.headline]
    if result.goodness is not None:
        lines.append(result.goodness.line())
    if result.stderr_note:
        lines.append(f"standard errors: {result.stderr_note}")
    rows = [(name, label(name), f"{result.values[name]:.6g}", f"{result.stderr[name]:.3g}", unit_text(parameter(name).unit),
             f"{result.start[name]:.6g}" if name in result.start else "", "nuisance" if name in result.nuisances else "")
            for name in result.names]
    for name in (n for n in result.extras if f"{n}.stderr" in result.extras):
        words, unit = _known(name)
        rows.append((name, words, f"{result.extras[name]:.6g}", f"{result.extras[f'{name}.stderr']:.3g}", unit, "", "derived"))
    text = "".join(f"<p>{html.escape(line)}</p>" for line in lines)
    warnings = "".join(f"<li>{html.escape(w)}</li>" for w in result.warnings)
    return (text + html_table(("parameter", "what", "value", "standard error", "unit", "start", "kind"), rows)
            + (f"<p>warnings:</p><ul>{warnings}</ul>" if warnings else ""))


def _known(name: str) -> tuple[str, str]:
    """A derived quantity's words and unit where the registry has it (``wrinkles.rms_m``), else none:
    a repr never raises."""
    try:
        words, unit = describe(name)
    except InputError:
        return "", ""
    return words, unit_text(unit)


def sensitivity_html(s: Any) -> str:
    """The rows of :meth:`Sensitivity.rows` as a table, with the seeds and the confidence."""
    header = ("parameter", "region", "dL/dp", "unit", "normalised", "note")
    rows = [[r[h] for h in header] for r in s.rows()]
    return html_table(header, rows, f"derivatives of the regions' mean radiance at {_values(s.at, s.units)}; "
                                    f"mean of {len(s.seeds)} seeds +- standard errors")


def _values(values: Mapping[str, float], units: Mapping[str, str]) -> str:
    return ", ".join(f"{name} = {v:.4g}{' ' + unit_text(units[name]) if unit_text(units[name]) else ''}" for name, v in values.items())


def light_curve_html(lc: Any) -> str:
    """Each point's swept value, phase angle, irradiance and magnitude with their errors ("unknown"
    with one seed)."""
    words, unit = describe(lc.against)
    against = f"{words} ({unit})"
    known = lc.seeds > 1
    rows = [(f"{x:.6g}", f"{phase:.3f}", f"{e:.5g}", f"{e_se:.2g}" if known else "unknown", f"{m:.4f}",
             f"{m_se:.3f}" if known else "unknown")
            for x, phase, e, e_se, m, m_se in zip(lc.x, lc.phase_angle_deg, lc.irradiance_w_m2, lc.irradiance_se_w_m2,
                                                  lc.magnitude, lc.magnitude_se)]
    caption = (f"light curve in {lc.band} at {lc.observer_range_m:.4g} m; "
               + (f"mean of {lc.seeds} seeds, Monte Carlo standard errors" if known else "one seed: the Monte Carlo error is unknown"))
    return html_table((against, "phase (deg)", "irradiance (W m^-2)", "+-", f"magnitude {lc.band}", "+-"), rows, caption)
