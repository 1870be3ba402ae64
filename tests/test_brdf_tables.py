"""BRDF tables as observations: each material model's BRDF against Mitsuba's own ``eval``, the two
table formats, a GGX table fitted back within 1 %, and the choice of the smallest adequate model."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from spacefit.errors import InputError
from spacefit.fitting.brdf_table import simulate_brdf_table
from spacefit.materials.measured import read_brdf_table
from spacefit.fitting.observations.brdf import compare_brdf_models, fit_brdf_table, fitted_material
from spacefit.fitting.report import format_result, write_table_fit
from spacefit.materials import Conductor, DiffuseConductor, Lambert, OrenNayar
from spacefit.materials.brdf import brdf
from spacefit.materials.conductor import fresnel_conductor
from spacefit.materials.registry import GOLD_ETA, GOLD_K
from spacefit.rendering.bsdf_eval import mitsuba_brdf

DATA = Path(__file__).resolve().parents[1] / "data" / "starlink-v1p5"


def directions(n: int, seed: int) -> np.ndarray:
    """Random unit vectors at least 3 deg from grazing, rounded to float32 as Mitsuba takes them."""
    v = np.random.default_rng(seed).normal(size=(n, 3))
    v[:, 2] = np.where(np.abs(v[:, 2]) < 0.05, np.copysign(0.05, v[:, 2]), v[:, 2])
    v /= np.linalg.norm(v, axis=1, keepdims=True)
    return v.astype(np.float32).astype(float)


@pytest.mark.parametrize("material", [
    Lambert(0.3),
    Conductor(2.05, 0.055, 0.08, 0.03),  # panel_thesis, anisotropic GGX
    Conductor(GOLD_ETA, GOLD_K, 0.2, 0.2),  # RGB
    Conductor(1.5, 3.0, 0.3, 0.1, "beckmann"),
    Conductor(0.18, 0.01, 0.14, 0.14),  # mli_thesis
    DiffuseConductor(0.1, 1.5, 0.0, 0.05, 0.07),
    OrenNayar((0.2, 0.4, 0.6), 0.7),  # spacefit's own Mitsuba plugin (rendering/materials.py)
], ids=["lambert", "ggx-aniso", "ggx-rgb", "beckmann-aniso", "mli", "diffuse+ggx", "oren-nayar"])
def test_brdf_equals_mitsubas_eval(material):
    """Both sides of the surface (twosided), opposite sides 0. JAX in float32, as Mitsuba computes:
    1e-5 relative where the value is above 1e-6 of the peak (Beckmann's tails below 1e-14 sr^-1
    round differently)."""
    wi, wo = directions(3000, 1), directions(3000, 2)
    ours, ref = np.asarray(brdf(material, wi, wo), dtype=float), mitsuba_brdf(material, wi, wo)
    assert np.array_equal(ours == 0, ref == 0) and (ref > 0).sum() > 700
    np.testing.assert_allclose(ours, ref, rtol=1e-5, atol=1e-6 * ref.max())


def test_fresnel_is_mitsubas():
    import mitsuba as mi

    mi.set_variant("llvm_ad_rgb")
    c = np.linspace(0.01, 1.0, 300, dtype=np.float32)
    ref = np.asarray(mi.fresnel_conductor(mi.Float(c), mi.Complex2f(0.18, 0.01)))
    np.testing.assert_allclose(np.asarray(fresnel_conductor(c, np.float32(0.18), np.float32(0.01))), ref, rtol=1e-6)


def test_starlink_format_reads_as_lumos_does():
    """Zenith phi, azimuth theta, a negative zenith on the far side: the chassis's peak at 75 deg
    incidence lies in the mirror direction (75 deg out, in the plane of incidence)."""
    table = read_brdf_table(DATA / "chassis_brdf.csv", floor=1e-4)
    assert len(table) == 709 and table.sigma is None  # 724 rows less the grazing and floor ones
    np.testing.assert_allclose(np.linalg.norm(table.wi, axis=1), 1.0)
    at75 = np.isclose(table.wi[:, 2], np.cos(np.radians(75.0)))
    assert table.wi[at75][0, 0] < 0  # azimuth -180: towards -x
    peak = table.wo[at75][np.argmax(table.value[at75])]
    assert np.degrees(np.arccos(peak[2])) == pytest.approx(75.0) and peak[0] > 0 and abs(peak[1]) < 1e-12
    assert len(read_brdf_table(DATA / "chassis_brdf.csv")) == 716  # only grazing dropped (the floor kept)


def test_general_format_and_its_errors(tmp_path):
    good = tmp_path / "t.csv"
    good.write_text("# measured at 633 nm\ntheta_i_deg,phi_i_deg,theta_o_deg,phi_o_deg,brdf_sr,sigma_sr\n"
                    "30,180,30,0,0.5,0.01\n30,180,0,0,0.1,0.002\n90,0,10,0,0.1,0.002\n")
    table = read_brdf_table(good)
    assert len(table) == 2 and table.sigma.tolist() == [0.01, 0.002]
    np.testing.assert_allclose(table.wi[0], [-0.5, 0.0, np.cos(np.radians(30))], atol=1e-12)
    cases = {
        "theta_i_deg,phi_i_deg,theta_o_deg,brdf_sr\n1,2,3,4\n": "lacks ['phi_o_deg']",
        "theta_i_deg,phi_i_deg,theta_o_deg,phi_o_deg,brdf_sr\n1,2,3,4,-1\n": "never negative, row 1 has -1",
        "theta_i_deg,phi_i_deg,theta_o_deg,phi_o_deg,brdf_sr\n1,2,3,x,1\n": "data row 1 must hold 5 numbers",
        "theta_i_deg,phi_i_deg,theta_o_deg,phi_o_deg,brdf_sr\n-5,2,3,4,1\n": "must lie in [0, 90]",
        "1 2 3 4\n": "must hold 5 numbers",
    }
    for i, (text, message) in enumerate(cases.items()):
        bad = tmp_path / f"bad{i}.csv"
        bad.write_text(text)
        with pytest.raises(InputError, match=message.replace("[", r"\[").replace("]", r"\]").replace("(", r"\(")):
            read_brdf_table(bad)


def test_a_ggx_table_is_fitted_back_and_chosen(tmp_path):
    """A GGX conductor's table with 0.5 % noise: alpha, eta, k back within 1 % and their errors; the
    comparison refuses Lambert (a misfit) and chooses GGX, the smallest model within the errors."""
    truth = Conductor(1.8, 2.5, 0.12, 0.12)
    table = simulate_brdf_table(truth, [5, 30, 45, 60, 75], np.arange(-85.0, 86.0, 5.0), [0.0, 30.0], relative_error=0.005, seed=1)
    comparison = compare_brdf_models(table, ("ggx", "lambert"))
    fit = comparison.fits["ggx"]
    assert fit.success and not fit.goodness.misfit, format_result(fit)
    # a table is fitted by least squares on its values, whatever the fit's image loss is called
    assert format_result(fit).splitlines()[0].startswith(f"{fit.status} (lm on the values' residuals, ")
    value = {name.rsplit(".", 1)[1]: v for name, v in fit.values.items()}
    assert fit.names == ("parts.sample.eta", "parts.sample.k", "parts.sample.alpha")  # the part's registered parameters
    for name, true in (("eta", 1.8), ("k", 2.5), ("alpha", 0.12)):
        assert value[name] == pytest.approx(true, rel=0.01)
        assert abs(value[name] - true) < 4 * fit.stderr[f"parts.sample.{name}"]
    assert fitted_material("ggx", fit) == Conductor(value["eta"], value["k"], value["alpha"], value["alpha"])
    assert comparison.fits["lambert"].goodness.misfit and comparison.chosen == "ggx"
    assert list(comparison.fits) == ["lambert", "ggx"] and "<- smallest within the errors" in comparison.table().splitlines()[2]
    folder = write_table_fit(tmp_path / "fit", fit, inputs={"table": table.source})
    assert sorted(p.name for p in folder.iterdir()) == ["fit.json", "report.txt"]
    saved = json.loads((folder / "fit.json").read_text())
    assert saved["values"]["parts.sample.alpha"] == pytest.approx(value["alpha"]) and saved["status"] == "converged"
    assert (folder / "report.txt").read_text().splitlines()[1].startswith("goodness of fit: chi^2/dof")
    with pytest.raises(InputError, match="previous spacefit table-fit result; pass --overwrite"):
        write_table_fit(folder, fit)
    assert write_table_fit(folder, fit, overwrite=True) == folder
    (tmp_path / "mine").mkdir()
    (tmp_path / "mine" / "notes.txt").write_text("kept")
    with pytest.raises(InputError, match=r"files spacefit did not write \(notes.txt\)"):
        write_table_fit(tmp_path / "mine", fit, overwrite=True)
    assert [p.name for p in (tmp_path / "mine").iterdir()] == ["notes.txt"]


def test_fit_arguments_are_checked():
    table = simulate_brdf_table(Lambert(0.2), [10.0], [0.0, 20.0, 40.0])
    with pytest.raises(InputError, match="`model` must be one of"):
        fit_brdf_table(table, "phong")
    with pytest.raises(InputError, match="`fixed`"):
        fit_brdf_table(table, "lambert", fixed={"k": 0.0})
    with pytest.raises(InputError, match="`relative_error`"):
        fit_brdf_table(table, "lambert", relative_error=-0.1)


def test_a_tabulated_brdf_gives_its_table_back_and_extends_it_by_harvey_offsets():
    """sf.TabulatedBRDF of the chassis's table: its own values at its own rows (the interpolation
    passes through them), the same value at a direction mirrored across the plane of incidence
    (isotropic), the value of the measured row at the same signed offset u = |beta - beta_0| out of
    the plane, a table's factor, and a refusal of tables it cannot read in-plane."""
    from spacefit.materials.measured import unit_vectors
    from spacefit.materials.tabulated import TabulatedBRDF, signed_offset

    table = read_brdf_table(DATA / "chassis_brdf.csv")
    tab = TabulatedBRDF.from_table(table)
    assert len(tab.incidence_rad) == 4 and [len(x) for x in tab.offset] == [179] * 4
    with jax_x64():
        evaluate = jax_jit(lambda wi, wo, scale: tab.evaluate(wi, wo, {"scale": scale}))
        np.testing.assert_allclose(np.asarray(evaluate(table.wi, table.wo, 1.0)), table.value, rtol=1e-6)
        wi = unit_vectors(np.array([41.4]), np.array([180.0]))
        wo = unit_vectors(np.array([30.0]), np.array([50.0]))
        u = float(np.asarray(signed_offset(wi, wo))[0])
        # the in-plane outgoing direction of the same offset: sin(zo) - sin(41.4 deg) = u
        zo = np.degrees(np.arcsin(u + np.sin(np.radians(41.4))))
        inplane = unit_vectors(np.array([zo]), np.array([0.0]))
        mirrored = wo * np.array([1.0, -1.0, 1.0])
        f = np.asarray(evaluate(np.tile(wi, (5, 1)), np.concatenate([wo, inplane, mirrored, wo, -wo]), np.array([1, 1, 1, 2, 1.0])))
        off, on = f[0], f[1]
        assert off == pytest.approx(on, rel=1e-9) and off > 0
        assert f[2] == pytest.approx(off, rel=1e-12)  # mirrored across the plane of incidence
        assert f[3] == pytest.approx(2 * off, rel=1e-12)  # the table's factor
        assert f[4] == 0.0  # opposite sides
    out_of_plane = simulate_brdf_table(Lambert(0.5), [30.0], [10.0, 40.0], [0.0, 90.0])
    with pytest.raises(InputError, match="plane of incidence"):
        TabulatedBRDF.from_table(out_of_plane)
    with pytest.raises(InputError, match="two or more"):
        TabulatedBRDF.from_table(simulate_brdf_table(Lambert(0.5), [30.0], [10.0]))
    with pytest.raises(InputError, match="`scale`"):
        TabulatedBRDF.from_table(table, scale=0.0)
    with pytest.raises(InputError, match="`offset\\[0\\]` and `log_value\\[0\\]`"):
        TabulatedBRDF(tab.incidence_rad[:1], (np.array([0.2, 0.1]),), (np.zeros(2),), "made")
    with pytest.raises(InputError, match="`incidence_rad` must be increasing"):
        TabulatedBRDF(tab.incidence_rad[::-1], tab.offset, tab.log_value, "made")


def jax_x64():
    import jax

    return jax.enable_x64(True)


def jax_jit(fn):
    import jax

    return jax.jit(fn)
