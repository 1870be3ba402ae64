"""What a pass adds: each material parameter's expected standard error from one frame, from the
whole pass, against the pass's span of phase angles and against the frames' noise, from the
Fisher information of the frames' Jacobians (no fit).

    python experiments/pass_identifiability.py --out experiments/results/pass_identifiability
    python experiments/pass_identifiability.py --frames 4 --size 16 --spp 8 --out /tmp/x   # a quick check

The pass is the panels case seen from an arc (:func:`spacefit.arc_pass`: 6 to 22 deg from the
zenith, the sun sinking from 80 to 70 deg), each frame with its own target attitude about x and y
free (nuisances, as a real pass has them). Frame k's Jacobian J_k (its three materials and its two
attitude angles) is computed twice with independent seeds; the Fisher information of a set of frames
is sum_k sym(J1_k^T J2_k) / sigma_k^2 (the cross form keeps the Monte Carlo noise of the columns
from counting as information), with the materials shared and each frame's attitude its own, and
the covariance its inverse. The noise is uniform per frame, sigma_k = p % of the frame's mean lit
radiance. Writes ``identifiability.csv`` and ``identifiability.png``.
"""

from __future__ import annotations

import argparse
import math
from pathlib import Path

import numpy as np
from studyio import save_figure, write_csv

import spacefit as sf
from spacefit.fitting.frames import FrameSpec, InProcess, frame_jacobian
from spacefit.scene.parameters import scene_value

MATERIALS = ["parts.panels.alpha_x", "parts.panels.alpha_y", "parts.legs.kd"]
POSE = ["target.attitude_x_deg", "target.attitude_y_deg"]


def phase_angle_deg(scene: sf.Scene) -> float:
    """The angle at the target (origin) between the sun and the observer, degrees."""
    to_sun = -np.asarray(scene.sun.direction, float)
    to_observer = np.asarray(scene.camera.position_m, float) - np.asarray(scene.target.position_m, float)
    cos = to_sun @ to_observer / (np.linalg.norm(to_sun) * np.linalg.norm(to_observer))
    return math.degrees(math.acos(np.clip(cos, -1.0, 1.0)))


def fisher(blocks: list[np.ndarray]) -> np.ndarray:
    """The joint Fisher information of frames whose own (m + 2) x (m + 2) blocks are ``blocks``
    (materials first, then the frame's two attitude angles): materials shared, attitudes per frame."""
    m, n = len(MATERIALS), len(blocks)
    F = np.zeros((m + 2 * n, m + 2 * n))
    for k, b in enumerate(blocks):
        idx = [*range(m), m + 2 * k, m + 2 * k + 1]
        F[np.ix_(idx, idx)] += b
    return F


def material_stderr(blocks: list[np.ndarray]) -> np.ndarray:
    """The materials' standard errors from the frames' Fisher blocks (inf where undetermined)."""
    F = fisher(blocks)
    w, v = np.linalg.eigh(F)
    if w.min() <= 1e-12 * w.max():
        return np.full(len(MATERIALS), np.inf)
    cov = (v / w) @ v.T
    return np.sqrt(np.diag(cov)[: len(MATERIALS)])


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--out", required=True, type=Path)
    p.add_argument("--frames", type=int, default=12)
    p.add_argument("--size", type=int, default=32)
    p.add_argument("--spp", type=int, default=64)
    p.add_argument("--noise", type=float, nargs="+", default=[0.5, 1.0, 2.0, 5.0, 10.0], help="% of the lit mean")
    args = p.parse_args()
    args.out.mkdir(parents=True, exist_ok=True)
    base = sf.load_scene("spacefit/synthetic/panels.toml",
                         {"render.resolution": [args.size, args.size], "camera.pixel_pitch_mm": 18.75 * 128 / args.size})
    frames = sf.arc_pass(args.frames)
    scenes = [base.with_values(f) for f in frames]
    names = (*MATERIALS, *POSE)
    executor = InProcess()
    unit_blocks, lit, phases = [], [], []
    for scene in scenes:
        spec = FrameSpec(scene, names, (0.0, 0.0, 0.0, 0.5, 0.5), args.spp, args.spp, "prb")
        x = np.array([scene_value(scene, n) for n in names])
        (img, J1), (_, J2) = executor.map(frame_jacobian, [spec, spec], [x, x], [1, 1001], [2, 1002])
        J1, J2 = J1.reshape(-1, len(names)).astype(float), J2.reshape(-1, len(names)).astype(float)
        unit_blocks.append(0.5 * (J1.T @ J2 + J2.T @ J1))  # at sigma = 1 W m^-2 sr^-1
        lit.append(float(img[img.max(axis=-1) > 0].mean()))
        phases.append(phase_angle_deg(scene))
        print(f"frame {len(phases) - 1}: phase angle {phases[-1]:.1f} deg, lit mean {lit[-1]:.3g} W m^-2 sr^-1", flush=True)
    truth = np.array([scene_value(base, n) for n in MATERIALS])
    rows = []

    def add(kind: str, members: list[int], noise: float) -> None:
        blocks = [unit_blocks[k] / (noise / 100.0 * lit[k]) ** 2 for k in members]
        se = material_stderr(blocks)
        span = max(phases[k] for k in members) - min(phases[k] for k in members)
        rows.append({"set": kind, "frames": len(members), "first": members[0], "phase_span_deg": round(span, 2), "noise_percent": noise,
                     **{f"se_{n.split('.')[-1]}_percent": round(float(100 * s / t), 4) for n, s, t in zip(MATERIALS, se, truth)}})

    for noise in args.noise:
        for k in range(len(scenes)):
            add("one frame", [k], noise)
        add("pass", list(range(len(scenes))), noise)
    mid = len(scenes) // 2
    for half in range(1, mid + 1):  # sub-passes round the middle frame, ever wider
        members = list(range(max(0, mid - half), min(len(scenes), mid + half)))
        add("sub-pass", members, 2.0)
    write_csv(args.out / "identifiability.csv", rows)
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, (ax1, ax2) = plt.subplots(1, 2, figsize=(9, 3.6))
    for c, n in enumerate(MATERIALS):
        key, color = f"se_{n.split('.')[-1]}_percent", f"C{c}"
        sub = [r for r in rows if r["set"] == "sub-pass"]
        ax1.plot([r["phase_span_deg"] for r in sub], [r[key] for r in sub], "o-", color=color, label=n.split(".", 1)[1])
        ones = [r[key] for r in rows if r["set"] == "one frame" and r["noise_percent"] == 2.0]
        ax1.plot([0.0] * len(ones), ones, "x", color=color, alpha=0.6)
        for kind, style in (("pass", "-"), ("one frame", ":")):
            pts = [(r["noise_percent"], r[key]) for r in rows if r["set"] == kind and (kind == "pass" or r["first"] == mid)]
            ax2.plot(*zip(*pts), style, marker="o", color=color, label=f"{n.split('.')[-1]}, {kind}")
    ax1.set(xlabel="span of phase angles in the (sub-)pass [deg]  (x: single frames)", ylabel="expected standard error [% of value]",
            yscale="log", title=f"noise 2 % of the lit mean, {args.size} px, {args.spp} spp")
    ax2.set(xlabel="noise [% of the frame's lit mean]", ylabel="expected standard error [% of value]", xscale="log", yscale="log",
            title=f"the pass ({len(scenes)} frames) and its middle frame")
    ax1.legend(fontsize=7)
    ax2.legend(fontsize=6)
    save_figure(fig, args.out / "identifiability.png")
    for r in rows:
        if r["set"] != "one frame" or r["noise_percent"] == 2.0:
            print(r)


if __name__ == "__main__":
    main()
