"""How results show in Jupyter (``_repr_html_``) and a scene's short repr: HTML tables of the same
cells as the text tables, every value with its unit and error, escaped.

The classes' ``_repr_html_`` methods call these (:class:`~spacefit.scene.schema.Scene`,
:class:`~spacefit.fitting.result.FitResult`, :class:`~spacefit.studies.sensitivity.Sensitivity`,
:class:`~spacefit.studies.lightcurve.LightCurve`), which sit above it: each function reads its object by
attribute (typed ``Any``) and imports none of them; nothing here imports more than the parameter registry.
"""

from __future__ import annotations

import html
from collections.abc import Mapping, Sequence
from typing import Any

from spacefit.errors import InputError
from spacefit.scene.parameters import label, parameter

# A value's unit where it is dimensionless, in tables: none.
DIMENSIONLESS = "1"
# What is not a registered parameter but may be swept or plotted: name -> (words, unit).
QUANTITIES = {"phase_angle_deg": ("solar phase angle", "deg"), "time_s": ("time", "s")}


def describe(name: str) -> tuple[str, str]:
    """The words and unit of a parameter (:func:`spacefit.scene.parameters.label`) or one of :data:`QUANTITIES`."""
    return QUANTITIES[name] if name in QUANTITIES else (label(name), parameter(name).unit)


def html_table(header: Sequence[str], rows: Sequence[Sequence[Any]], caption: str = "") -> str:
    """An HTML table of ``rows`` (cells as text, escaped) under ``header``, with a ``caption``."""
    cap = f"<caption style='text-align:left'>{html.escape(caption)}</caption>" if caption else ""
    head = "".join(f"<th style='text-align:left'>{html.escape(h)}</th>" for h in header)
    body = "".join("<tr>" + "".join(f"<td style='text-align:left'>{html.escape(str(c))}</td>" for c in row) + "</tr>"
                   for row in rows)
    return f"<table>{cap}<thead><tr>{head}</tr></thead><tbody>{body}</tbody></table>"


def unit_text(unit: str) -> str:
    """A unit as a table shows it: "" for a dimensionless one."""
    return "" if unit == DIMENSIONLESS else unit


def _vector(v: Sequence[float]) -> str:
    return "(" + ", ".join(f"{x:g}" for x in v) + ")"


def scene_repr(scene: Any) -> str:
    """One short line: the film, the camera, the sun, the parts and their materials, the wrinkles."""
    r, c = scene.render, scene.camera
    parts = ", ".join(f"{name} ({p.material.__class__.__name__.lower()})" for name, p in scene.parts.items())
    wrinkles = f"wrinkles D {scene.wrinkles.D:g} G {scene.wrinkles.G:g} m on {', '.join(scene.wrinkles.parts)}" \
        if scene.wrinkles.enabled else "no wrinkles"
    return (f"Scene({r.resolution[0]}x{r.resolution[1]} px, {r.spp} spp; camera at {_vector(c.position_m)} m; "
            f"sun {scene.sun.irradiance_w_m2:g} W m^-2; parts {parts}; {wrinkles})")


def scene_html(scene: Any) -> str:
    """The scene's repr line, then each section's values (``Scene.to_dict``) in a table."""
    rows = []
    for section, values in scene.to_dict().items():
        items = values.items() if section != "parts" else (  # a lander's part it lacks is `parts.NAME = false`
            row for part, t in values.items() for row in (((f"{part}.{k}", v) for k, v in t.items()) if isinstance(t, dict) else [(part, t)]))
        rows += [(section, key, _vector(v) if isinstance(v, list) and all(isinstance(x, float) for x in v) else v)
                 for key, v in items]
    return f"<p>{html.escape(scene_repr(scene))}</p>" + html_table(("section", "key", "value"), rows)


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
