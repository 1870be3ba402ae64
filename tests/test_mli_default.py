"""The default wrinkles look like crumpled MLI (issue 13); the thesis's literal G = 10 m folds the body.

The default body's rms slope (eq. 2-1 in closed form) lies in the documented range and its
displaced faces do not fold; the literal preset's fold fraction is measured, recorded and warned
about; :func:`fold_fraction` itself is pinned on a box whose faces are all, or none, turned over.
"""

from __future__ import annotations

import warnings
from pathlib import Path

import pytest
import trimesh

import spacefit as sf
from spacefit.geometry.wrinkle import FOLD_WARN_FRACTION, MLI_SLOPE_RANGE, fold_fraction, refine
from spacefit.scene.assembly import assemble

LITERAL = Path(__file__).resolve().parents[1] / "data" / "scenes" / "thesis-literal.toml"


def wm_values(scene: sf.Scene) -> dict[str, float]:
    w = scene.wrinkles
    return {"gamma": w.gamma, "M": w.M, "L": w.L, "Ls": w.Ls}


def test_default_body_slope_is_crumpled_foil_and_does_not_fold():
    scene = sf.default_scene()
    w = scene.wrinkles
    slope = float(sf.wm_rms_slope(w.D, w.G, **wm_values(scene)))
    assert MLI_SLOPE_RANGE[0] <= slope <= MLI_SLOPE_RANGE[1]
    with warnings.catch_warnings():
        warnings.filterwarnings("error", message=".*fold over")
        assembly = assemble(scene)
    assert 0.0 <= assembly.folds["body"] < FOLD_WARN_FRACTION


def test_literal_preset_is_the_thesis_values_and_warns_with_its_fold_fraction():
    scene = sf.load_scene(LITERAL)
    w, d = scene.wrinkles, sf.default_scene().wrinkles
    assert w.G == 10.0 and (w.D, w.gamma, w.M, w.L, w.Ls) == (d.D, d.gamma, d.M, d.L, d.Ls)
    assert float(sf.wm_rms_slope(w.D, w.G, **wm_values(scene))) > 10 * MLI_SLOPE_RANGE[1]
    with pytest.warns(UserWarning, match=r"% of its wrinkled faces fold over") as caught:
        assembly = assemble(scene)
    fraction = assembly.folds["body"]
    assert fraction > FOLD_WARN_FRACTION
    assert f"{100 * fraction:.1f} %" in str(caught[0].message)


def test_render_json_records_the_fold_fraction(tmp_path):
    scene = sf.load_scene(LITERAL, {"render.resolution": [24, 24], "camera.pixel_pitch_mm": 100.0, "render.spp": 1})
    with pytest.warns(UserWarning, match="fold over"):
        _, sidecar = sf.render_to_folder(scene, tmp_path / "out", quiet=True)
    recorded = sidecar["fold_fraction"]
    assert recorded["parts"]["body"] == assemble(scene).folds["body"] > recorded["warn_above"]
    assert any("fold over" in note for note in sidecar["warnings"])


def test_fold_fraction_counts_faces_turned_over_the_surface_under_them():
    """Undisplaced: nothing folds. The box reflected through its centre puts every face on the
    opposite side with its normal unchanged, so every face shows its back: all fold but a few
    at the box's edges, whose nearest sample lies on a perpendicular face."""
    box = trimesh.creation.box(extents=(1.0, 0.8, 0.6))
    ref = refine(box.vertices, box.faces, 0.1)
    assert fold_fraction(ref, ref.vertices) == 0.0
    assert fold_fraction(ref, -ref.vertices) > 0.95
    half = ref.vertices.copy()
    top = ref.vertices[:, 2] > 0.29
    half[top, 2] = -0.6  # the top face pushed through the bottom: its faces (and the sides' walls) turn over
    assert 0.0 < fold_fraction(ref, half) < 1.0


def test_fold_fraction_grows_with_G():
    scene = sf.default_scene()
    folds = [assemble(scene.with_values({"wrinkles.G": G})).folds["body"] for G in (1e-5, 1e-3)]
    assert folds[0] < folds[1]
