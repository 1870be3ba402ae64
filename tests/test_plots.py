"""Figures that go into a paper and results in Jupyter: every figure function draws into the axes or
figure it is given and returns them, crops images to the target (or not), labels axes in words with
units, draws error bars and truths; the sensitivity chart's steps; tables without stray units and
with exact zeros; rich HTML reprs. All on results made by hand (no render): fast."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest
from matplotlib.axes import Axes
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure
from matplotlib.text import Text

import spacefit as sf
from spacefit.fitting.result import FitResult
from spacefit.fitting.status import Status
from spacefit.html_tables import html_table
from spacefit.plotting import PlainLogFormatter, axis_label, target_box, unit_label
from spacefit.scene.parameters import PARAMETERS
from spacefit.studies.lightcurve import LightCurve
from spacefit.studies.sensitivity import Sensitivity

SIZE = 64
BLOB = (slice(30, 40), slice(20, 28))  # rows, columns of the target in the film


def film(value: float = 1.0) -> np.ndarray:
    image = np.zeros((SIZE, SIZE, 3))
    image[BLOB] = value
    return image


def fit_result(units: str = "W m^-2 sr^-1") -> FitResult:
    names = ("parts.body.kd", "target.attitude_z_deg")
    history = [{"step": k, "loss": 10.0 / (k + 1), "accepted": k != 2, "loss_noise": 0.1,
                "values": {"parts.body.kd": 0.3 + 0.05 * k, "target.attitude_z_deg": 2.0 - 0.5 * k}} for k in range(4)]
    return FitResult(names, {"parts.body.kd": 0.45, "target.attitude_z_deg": 0.5}, {"parts.body.kd": 0.01, "target.attitude_z_deg": 0.2},
                     np.eye(2), True, Status.CONVERGED, [], history, [film(1.1)], 1.0, "lm", "pixel", 4, 0.1,
                     start={"parts.body.kd": 0.3, "target.attitude_z_deg": 2.0}, units=[units], residuals=[film(-0.1)])


def sensitivity() -> Sensitivity:
    """Two parts: D strong (28 per unit at 2.5), the attitude unresolved, the albedo of ``a`` exactly 0 on ``b``."""
    names = ("wrinkles.D", "parts.a.kd", "target.attitude_z_deg")
    derivative = np.stack([film(v) for v in (2.0, 0.5, -0.1)]).astype(np.float32)
    d = np.array([[28.0, 3.0, 28.0], [0.5, 0.0, 0.5], [-0.1, 0.05, -0.1]])
    se = np.array([[1.0, 0.5, 1.0], [0.01, 0.0, 0.01], [0.2, 0.2, 0.2]])
    mean = np.array([1.0, 0.5, 1.0])
    return Sensitivity(names, {"wrinkles.D": "1", "parts.a.kd": "1", "target.attitude_z_deg": "deg"},
                       {"wrinkles.D": 2.5, "parts.a.kd": 0.4, "target.attitude_z_deg": 0.0}, ((1, 2), (3, 4)),
                       film().astype(np.float32), derivative, derivative * 0.01, ("a", "b", "target"), np.array([80, 10, 90]),
                       mean, d, se, d * 2.5, se * 2.5, {"wrinkles.D": "1", "parts.a.kd": "1", "target.attitude_z_deg": "rad^-1"}, 3.18)


def light_curve(seeds: int = 4) -> LightCurve:
    x = np.array([10.0, 40.0, 70.0])
    e = np.array([1e-9, 8e-10, 5e-10])
    se = e * 0.02 if seeds > 1 else np.full(3, np.nan)
    m = -26.74 - 2.5 * np.log10(e / 5.0)
    return LightCurve("phase_angle_deg", x, e, m, x, "V", -26.74, 25.0, 25.0, 5.0, None, se, 1.086 * se / e, seeds)


def frame_rows() -> list[dict[str, float]]:
    return [{"time_s": 10.0 * k, "chi2_dof": 1.0 + 0.1 * k, "target.attitude_z_deg": 0.1 * k, "target.attitude_z_deg.stderr": 0.05}
            for k in range(3)]


# Each figure function: name -> (call with keyword arguments, how many axes it draws, the counts of Axes it takes).
FIGURES = {
    "plot_comparison": (lambda **kw: sf.plot_comparison(fit_result(), [film()], **kw), 3, "3"),
    "plot_convergence": (lambda **kw: sf.plot_convergence(fit_result(), **kw), 3, "3"),
    "plot_frames": (lambda **kw: sf.plot_frames(frame_rows(), **kw), 2, "2"),
    "Sensitivity.figure": (lambda **kw: sensitivity().figure(**kw), 4, "4"),
    "LightCurve.figure": (lambda **kw: light_curve().figure(**kw), 2, "1 or 2"),
}


@pytest.mark.parametrize("name", FIGURES)
def test_every_figure_draws_into_the_axes_given_and_returns_them(name):
    draw, count, counts = FIGURES[name]
    fig = Figure()
    mine = fig.subplots(1, count + 1)  # the user's own layout, one more panel than it needs
    axes = draw(ax=mine[1:])
    assert np.size(axes) == count and all(a is b for a, b in zip(np.ravel(axes), mine[1:]))
    assert all(a.has_data() or a.get_title() for a in mine[1:]) and not mine[0].has_data()  # drawn there, nowhere else
    assert len(fig.axes) >= count + 1 and fig._suptitle is None  # the user's figure keeps its own title
    one = Figure().add_subplot()
    if "1" in counts.split(" or "):
        assert list(np.ravel(draw(ax=one))) == [one]  # a single Axes is taken as is
    else:
        with pytest.raises(sf.InputError, match=rf"^`ax` must be {counts} matplotlib Axes here \(one per panel\), got 1\.$"):
            draw(ax=one)
    with pytest.raises(sf.InputError, match=rf"^`ax` must be {counts} matplotlib Axes here \(one per panel\), got {count + 1}\.$"):
        draw(ax=list(mine))
    with pytest.raises(sf.InputError, match=f"^`ax` must be a matplotlib Axes, or an array of {counts} "):
        draw(ax=["left", "right"][:count] * count)
    with pytest.raises(sf.InputError, match="not both"):
        draw(ax=mine[1:], fig=fig)


def test_an_array_of_axes_in_any_shape_is_taken_panel_by_panel():
    """plt.subplots(2, 2)'s array as it comes (2-D), a tuple, and a list of rows: row by row."""
    grid = Figure().subplots(2, 2)
    assert list(sensitivity().figure(ax=grid)) == list(grid.ravel())
    assert list(light_curve().figure(ax=tuple(grid[0]))) == list(grid[0])
    rows = Figure().subplots(3, 1, squeeze=False)
    assert list(sf.plot_convergence(fit_result(), ax=[list(r) for r in rows])) == list(rows.ravel())


def test_a_light_curve_in_one_axes_is_its_magnitudes_with_the_irradiance_on_a_second_axis():
    curve = light_curve()
    one = Figure().add_subplot()
    (drawn,) = curve.figure(ax=one)
    assert drawn is one and drawn.yaxis_inverted() and "magnitude" in drawn.get_ylabel()
    np.testing.assert_allclose(drawn.containers[0].lines[0].get_ydata(), curve.magnitude)
    (second,) = drawn.child_axes
    assert "irradiance" in second.get_ylabel()
    FigureCanvasAgg(one.figure).draw()  # a second axis takes its limits when drawn
    # its limits are the irradiances of the magnitude axis's (E = E_sun 10^(-0.4 (m - m_sun)))
    irradiance = curve.sun_irradiance_w_m2 * 10.0 ** (-0.4 * (np.array(drawn.get_ylim()) - curve.sun_magnitude))
    np.testing.assert_allclose(sorted(second.get_ylim()), sorted(irradiance), rtol=1e-9)


def test_frames_without_a_known_noise_draw_no_chi2_panel_and_say_why():
    rows = [{k: v for k, v in row.items() if k != "chi2_dof"} | {"chi2_dof": math.nan} for row in frame_rows()]
    axes = sf.plot_frames(rows)
    assert len(axes) == 1 and "attitude" in axes[0].get_ylabel() and "noise is unknown" in axes[0].get_title()
    assert "chi" not in " ".join(a.get_ylabel() for a in axes[0].figure.axes)
    with pytest.raises(sf.InputError, match="got 2"):
        sf.plot_frames(rows, ax=Figure().subplots(2, 1))
    with pytest.raises(sf.InputError, match="nothing to draw"):
        sf.plot_frames([{"frame": 0, "time_s": 0.0, "chi2_dof": math.nan}])
    assert len(sf.plot_frames(frame_rows())) == 2  # with the noise known: its chi^2 / dof too


def test_a_frame_table_reads_back_as_written(tmp_path):
    from spacefit.fitting.pass_report import write_frame_table

    rows = [{"frame": k, "file": f"f{k}.fits", "time": "", "time_s": 10.0 * k, "chi2_dof": 1.0 + 0.1 * k, "misfit": k == 2,
             "render_noise": 1 / 3, "target.attitude_z_deg": 0.1 * k, "target.attitude_z_deg.stderr": math.inf if k else math.nan}
            for k in range(3)]
    del rows[1]["chi2_dof"]  # a frame without its goodness (none in the fit)
    write_frame_table(tmp_path / "frames.csv", rows)
    read = sf.read_frame_table(tmp_path / "frames.csv")
    assert [list(r) for r in read] == [list(r) for r in rows] and math.isnan(read[0]["target.attitude_z_deg.stderr"])
    assert read[1:] == rows[1:] and {k: v for k, v in read[0].items() if "stderr" not in k} == {
        k: v for k, v in rows[0].items() if "stderr" not in k}  # floats exactly, types as frame_table's
    assert len(sf.plot_frames(read)) == 2
    (tmp_path / "frames.csv").write_text("frame,misfit,time_s\n0,maybe,1.0\n")
    with pytest.raises(sf.InputError, match=r"line 2: misfit = 'maybe' is not True or False\.$"):
        sf.read_frame_table(tmp_path / "frames.csv")
    with pytest.raises(sf.InputError, match="no frame table there"):
        sf.read_frame_table(tmp_path / "nothing.csv")


@pytest.mark.parametrize("name", FIGURES)
def test_every_figure_lays_out_its_panels_in_the_figure_given(name):
    draw, count, _ = FIGURES[name]
    outer = Figure()
    left, right = outer.subfigures(1, 2)
    axes = np.asarray(draw(fig=right)).ravel()
    assert len(axes) == count and all(isinstance(ax, Axes) and ax.figure is right for ax in axes)
    assert not left.axes  # nothing drawn outside it
    own = np.asarray(draw()).ravel()  # without either: a Figure of its own, made without pyplot
    assert isinstance(own[0].figure, Figure) and own[0].figure is not outer
    with pytest.raises(sf.InputError, match="`fig` must be a matplotlib Figure"):
        draw(fig="figure.png")


def test_images_are_cropped_to_the_target_unless_asked_for_the_whole_film():
    # the target is columns 20..27, rows 30..39: with a margin of 15 % of its larger side (2 px)
    assert target_box([film()]) == (18, 28, 30, 42)
    # a sensor's constant bias is background, noise below 1 % of the target is too
    rng = np.random.default_rng(1)
    assert target_box([film(1000.0) + 100.0 + rng.normal(0, 2.0, (SIZE, SIZE, 3))]) == (18, 28, 30, 42)
    assert target_box([np.zeros((SIZE, SIZE))]) == (0, 0, SIZE, SIZE)  # nothing seen: the whole film
    cropped = sf.plot_comparison(fit_result(), [film()])[0, 0]
    assert cropped.get_xlim() == (17.5, 29.5) and cropped.get_ylim() == (41.5, 27.5)  # film pixel coordinates, y down
    whole = sf.plot_comparison(fit_result(), [film()], crop=False)[0, 0]
    assert whole.get_xlim() == (-0.5, SIZE - 0.5) and whole.get_ylim() == (SIZE - 0.5, -0.5)
    assert sf.plot_comparison(fit_result(), [film()])[0, 2].get_xlim() == (17.5, 29.5)  # the residual's crop too
    assert sensitivity().figure()[0].get_xlim() == (17.5, 29.5)
    assert sensitivity().figure(crop=False)[0].get_xlim() == (-0.5, SIZE - 0.5)
    with pytest.raises(sf.InputError, match="`crop`"):
        sf.plot_comparison(fit_result(), [film()], crop="yes")


def test_the_comparison_s_residual_column_is_the_fit_s_residuals_on_a_symmetric_scale_in_their_unit():
    """The picture of residuals.fits: FitResult.residuals (reference - fit: the fit renders the target 0.1 above its
    reference, -0.1 there), grey where not fitted, on a colour scale symmetric about 0 with a colour bar in the
    observation's unit; a fit without residuals (one interrupted) shows the reference less its render."""
    result = fit_result()
    result.residuals[0][BLOB[0].start, BLOB[1].start] = np.nan  # a pixel the mask left out
    panel = sf.plot_comparison(result, [film()])[0, 2]
    image = panel.get_images()[0]
    shown = image.get_array()
    assert shown.mask.sum() == 1 and shown.min() == pytest.approx(-0.1) and shown.max() == pytest.approx(0.0)
    assert image.cmap.get_bad()[:3] == pytest.approx((0.6, 0.6, 0.6))  # grey where not fitted
    assert image.norm.vmin == -image.norm.vmax == pytest.approx(-0.1) and image.cmap.name.startswith("RdBu_r")
    assert panel.get_title() == "reference - fit, observation 0"
    colorbar = [ax for ax in panel.figure.axes if ax.get_ylabel().startswith("reference - fit")]
    assert [ax.get_ylabel() for ax in colorbar] == [f"reference - fit ({unit_label('W m^-2 sr^-1')})"]
    interrupted = sf.plot_comparison(dataclasses.replace(fit_result(), residuals=[]), [film()])[0, 2].get_images()[0]
    np.testing.assert_allclose(interrupted.get_array(), fit_result().residuals[0].mean(axis=-1)[28:42, 18:30], atol=1e-6)


def test_axes_are_labelled_in_words_with_units():
    assert axis_label("target.attitude_z_deg") == "target attitude about z (deg)"
    assert axis_label("parts.panels.kd") == "albedo kd of panels"  # dimensionless: no "(1)"
    assert axis_label("image.offset_w_m2_sr@1") == "image offset, observation 1 (W m⁻² sr⁻¹)"
    assert axis_label("phase_angle_deg") == "solar phase angle (deg)"
    assert unit_label("1") == "" and unit_label("W m^-2") == "W m⁻²"
    assert all(p.label for p in PARAMETERS.values())  # every registered parameter has its words
    convergence = sf.plot_convergence(fit_result())
    assert [ax.get_ylabel().replace("\n", " ") for ax in convergence[1:]] == ["albedo kd of body", "target attitude about z (deg)"]
    stopped = sf.plot_convergence(dataclasses.replace(fit_result(), status=Status.NO_BETTER_POINT))
    assert stopped[0].get_title() == "lm, pixel loss: converged: no better point"  # the verdict in words, not its code name
    lc = light_curve().figure()
    assert lc[0].get_xlabel() == "solar phase angle (deg)" and "(mag" in lc[1].get_ylabel()
    assert lc[0].get_ylabel() == f"irradiance at the observer ({unit_label('W m^-2')})"  # the one home of units' text
    frames = sf.plot_frames(frame_rows())
    assert frames[0].get_ylabel() == "target attitude about z (deg)" and frames[-1].get_xlabel() == "time since the first frame (s)"
    sens = sensitivity().figure()
    colorbars = [ax.get_ylabel() for ax in sens[0].figure.axes if ax not in list(sens)]
    assert "W m⁻² sr⁻¹ per deg" in colorbars and not any("per 1" in c for c in colorbars)
    assert "W m⁻² sr⁻¹" in sf.plot_comparison(fit_result(), [film()])[0, 0].get_title()
    dn = sf.plot_comparison(fit_result("DN"), [film()])
    assert "(DN)" in [ax.get_ylabel() for ax in dn[0, 0].figure.axes][-1]
    texts = [ax.get_xlabel() + ax.get_ylabel() for ax in [*convergence, *lc, *frames, *sens]]
    assert not any(raw in text for text in texts for raw in ("_deg", "_px", "_w_m2", "parts.", "target."))


def test_convergence_overlays_truths_and_the_standard_error():
    axes = sf.plot_convergence(fit_result(), truths={"target.attitude_z_deg": 0.3})
    kd, angle = axes[1], axes[2]
    assert "truth" in angle.get_legend_handles_labels()[1] and "truth" not in kd.get_legend_handles_labels()[1]
    truth = [line for line in angle.lines if line.get_label() == "truth"]
    assert truth[0].get_ydata()[0] == 0.3
    band = [p for p in angle.patches if p.get_label().startswith("fit +- 1 standard error")]
    assert band and band[0].get_extents().height > 0
    # the column's legend once, in its first panel, saying what the band and the (second panel's) truth are
    assert [t.get_text() for t in kd.get_legend().get_texts()] == ["fit +- 1 standard error", "truth"]
    assert angle.get_legend() is None
    canvas = FigureCanvasAgg(kd.figure)
    canvas.draw()
    for panel in (kd, angle):  # each parameter's words within its panel's height, not into its neighbours'
        assert panel.yaxis.label.get_window_extent(canvas.get_renderer()).height <= panel.get_window_extent().height
    # the steps numbered once, under the column (the panels share them)
    assert [p.xaxis.get_tick_params()["labelbottom"] for p in (kd, angle)] == [False, True]
    with pytest.raises(sf.InputError, match="truths"):
        sf.plot_convergence(fit_result(), truths={"wrinkles.D": 2.5})
    with pytest.raises(sf.InputError, match="truths"):
        sf.plot_convergence(fit_result(), truths={"parts.body.kd": math.nan})


def many_parameters(count: int) -> FitResult:
    """A fit of ``count`` parameters with long names and values of every size: tiny, around 1e4 with a spread that
    matplotlib writes as an offset ("+1.23456e4"), negative and large."""
    kinds = ("parts.solar_array_panel_number_{}_of_the_spacecraft_bus.alpha_x", "image.offset_w_m2_sr@{}", "parts.p{}.kd",
             "sun.irradiance_w_m2@{}")
    names = tuple(kinds[i % 4].format(i) for i in range(count))
    scales = [(3e-6, 1e-6), (12345.678, 0.01), (0.3, 0.2), (-2.5e5, 4e4)]
    value = {name: (lambda k, i=i: scales[i % 4][0] + scales[i % 4][1] * (-0.7) ** k) for i, name in enumerate(names)}
    history = [{"step": k + 1, "loss": 10.0 / (k + 1), "accepted": True, "values": {n: value[n](k) for n in names}} for k in range(6)]
    final = {n: value[n](5) for n in names}
    return FitResult(names, final, {n: 0.05 * scales[i % 4][1] for i, n in enumerate(names)}, np.eye(count), True, Status.CONVERGED, [],
                     history, [film(1.1)], 1.0, "lm", "pixel", 6, 0.1, start={n: value[n](0) for n in names}, units=["W m^-2 sr^-1"])


@pytest.mark.parametrize("count", [1, 3, 8, pytest.param(64, marks=pytest.mark.slow)])
def test_the_convergence_figure_s_labels_are_whole_and_apart_for_any_count_of_parameters(count, monkeypatch):
    """Its layout, computed once from its labels' sizes: every text it draws (tick labels, offset texts, axis labels,
    titles, the legends) lies inside the figure and clear of every other text and every other panel."""
    result = many_parameters(count)
    figure = sf.plot_convergence(result, truths={result.names[0]: result.values[result.names[0]]})[0].figure
    drawn = []
    draw = Text.draw

    def recording(text: Text, renderer) -> None:
        draw(text, renderer)
        if text.get_visible() and text.get_text():
            drawn.append((text, text.get_window_extent(renderer)))

    monkeypatch.setattr(Text, "draw", recording)
    FigureCanvasAgg(figure).draw()
    width, height = figure.bbox.width, figure.bbox.height
    texts = {text.get_text() for text, _ in drawn}
    assert {"step", "loss, 0.5 sum of squared residuals", "truth"} <= texts and ("+1.23456e4" in texts) == (count > 1)
    for text, box in drawn:  # whole: within the figure (to the rounding of a pixel)
        assert -1 <= box.x0 and box.x1 <= width + 1 and -1 <= box.y0 and box.y1 <= height + 1, text.get_text()
    boxes = np.array([box.extents for _, box in drawn]) + [0.5, 0.5, -0.5, -0.5]  # apart by more than a pixel's rounding
    apart = ((boxes[:, None, 2] <= boxes[None, :, 0]) | (boxes[None, :, 2] <= boxes[:, None, 0])
             | (boxes[:, None, 3] <= boxes[None, :, 1]) | (boxes[None, :, 3] <= boxes[:, None, 1]))
    np.fill_diagonal(apart, True)
    overlapping = [(drawn[i][0].get_text(), drawn[j][0].get_text()) for i, j in zip(*np.nonzero(~apart))]
    assert not overlapping
    for text, box in drawn:  # no text in another panel
        others = [ax for ax in figure.axes if ax is not text.axes]
        assert not any(box.padded(-0.5).overlaps(ax.bbox) for ax in others), text.get_text()


def test_a_long_verdict_is_drawn_whole_in_the_figure_s_title():
    result = dataclasses.replace(fit_result(), status=Status.NO_BETTER_POINT)  # its words: 250 characters
    figure = sf.plot_comparison(result, [film()]).flat[0].figure
    canvas = FigureCanvasAgg(figure)
    canvas.draw()
    title = figure.get_suptitle()
    assert title.replace("\n", " ").endswith(str(Status.NO_BETTER_POINT)) and "\n" in title
    inside = figure.bbox.expanded(1.001, 1.001)  # within the rounding of a pixel
    box = next(t for t in figure.texts if t.get_text() == title).get_window_extent(canvas.get_renderer())
    assert inside.x0 <= box.x0 and box.x1 <= inside.x1 and box.y1 <= inside.y1


def test_log_axes_are_labelled_as_matplotlib_labels_them_in_plain_text():
    formatter = PlainLogFormatter()
    assert [formatter(x) for x in (1e5, 3e4, 2e-4, 1.0, -2e3)] == ["10⁵", "3×10⁴", "2×10⁻⁴", "10⁰", "−2×10³"]
    assert PlainLogFormatter(labelOnlyBase=True)(2e4) == ""  # asked for the decades alone
    loss = sf.plot_convergence(fit_result())[0]
    for axes in (loss, light_curve().figure()[0]):  # the fit's loss, a light curve's irradiance
        FigureCanvasAgg(axes.figure).draw()
        labels = [t.get_text() for t in [*axes.yaxis.get_ticklabels(), *axes.yaxis.get_ticklabels(minor=True)] if t.get_text()]
        assert labels and not any("$" in text for text in labels)


def test_light_curve_error_bars_only_where_errors_are_known():
    assert len(light_curve(4).figure()[1].containers) == 1
    errorbar = light_curve(4).figure()[0].containers[0]
    assert errorbar.has_yerr and not light_curve(1).figure()[0].containers[0].has_yerr


def test_sensitivity_chart_steps_by_range_or_a_stated_step_not_by_value():
    sens = sensitivity()
    steps = sens.chart_steps()
    assert steps["wrinkles.D"] == (pytest.approx(0.1), "a tenth of its range (2, 3)")
    assert steps["parts.a.kd"] == (pytest.approx(0.1), "a tenth of its range (0, 1)")
    assert steps["target.attitude_z_deg"] == (0.1, "a change that matters")  # the value is 0: no value to divide by
    bars = sens.figure()[-1]
    heights = np.array([p.get_height() for p in bars.patches]).reshape(3, 3)  # parameter x region
    # percent change of the region's mean radiance for the step: D's 28 per unit x 0.1, not x its value 2.5
    np.testing.assert_allclose(heights[:, 0], [280.0, 5.0, -1.0])
    assert heights[1, 1] == 0.0  # an exact zero is drawn as zero
    given = sens.figure(steps={"wrinkles.D": 0.01})[-1]
    assert given.patches[0].get_height() == pytest.approx(28.0)
    assert any("step 0.01 (as given)" in t for t in given.get_legend_handles_labels()[1])
    with pytest.raises(sf.InputError, match="steps"):
        sens.figure(steps={"wrinkles.D": -1.0})
    with pytest.raises(sf.InputError, match="steps"):
        sens.figure(steps={"parts.b.kd": 0.1})


def test_sensitivity_table_has_no_stray_unit_and_reports_exact_zeros_as_zero():
    sens = sensitivity()
    rows = {(r["parameter"], r["region"]): r for r in sens.rows()}
    zero = rows[("parts.a.kd", "b")]
    assert zero["dL/dp"] == "0" and zero["normalised"] == "0" and zero["note"] == ""
    assert rows[("wrinkles.D", "a")]["unit"] == "W m^-2 sr^-1" and rows[("target.attitude_z_deg", "a")]["unit"] == "W m^-2 sr^-1 per deg"
    assert rows[("target.attitude_z_deg", "a")]["note"] == "UNRESOLVED (noise)"
    assert not rows[("wrinkles.D", "a")]["normalised"].endswith(" 1")
    text = sens.table()
    assert "per 1" not in text and not any(line.rstrip().endswith(" 1") for line in text.splitlines())
    lines = [line for line in text.splitlines() if line.startswith("parts.a.kd") and " b " in line]
    assert lines and "UNRESOLVED" not in lines[0]
    assert sens.exact_zero.tolist() == [[False, False, False], [False, True, False], [False, False, False]]


def test_rich_reprs_in_jupyter():
    scene = sf.load_case("panels").truth_scene
    assert len(repr(scene)) < 200 and repr(scene).startswith("Scene(128x128 px") and "legs (lambert)" in repr(scene)
    page = scene._repr_html_()
    assert page.count("<table>") == 1 and "focal_length_mm" in page and "parts" in page
    result = fit_result()
    result.extras.update({"wrinkles.rms_m": 2e-5, "wrinkles.rms_m.stderr": 1e-6, "other": 1.0, "other.stderr": 0.5})
    fit = result._repr_html_()
    assert "<table>" in fit and "albedo kd of body" in fit and "0.45" in fit and "deg" in fit and "converged" in fit
    derived = "<td style='text-align:left'>" + "</td><td style='text-align:left'>".join(
        ["wrinkles.rms_m", "rms height", "2e-05", "1e-06", "m", "", "derived"]) + "</td>"
    assert derived in fit and ">other<" in fit  # a derived value the registry lacks is shown without words or unit
    sens = sensitivity()._repr_html_()
    assert "UNRESOLVED (noise)" in sens and "W m^-2 sr^-1 per deg" in sens and sens.count("<tr>") == 1 + 9
    lc = light_curve(1)._repr_html_()
    assert "solar phase angle (deg)" in lc and "unknown" in lc and lc.count("<tr>") == 1 + 3
    assert "&lt;b&gt;" in html_table(["a"], [["<b>"]])  # escaped
