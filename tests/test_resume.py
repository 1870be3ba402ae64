"""A fit interrupted and resumed (``--resume``) ends as the uninterrupted one: the checkpoint keeps its
steps' history, and the resumed solve's stop rule and verdict go on from it."""

from __future__ import annotations

import json
import os
import signal
from pathlib import Path

import pytest
from helpers import write_sphere_fit_case

from spacefit.cli import main
from spacefit.pipeline import Checkpoint

STOP_AFTER = 3  # steps before the interruption


@pytest.fixture(scope="module")
def fit_case(tmp_path_factory) -> Path:
    """A Lambert sphere from kd 0.2 to 0.5 at 24 x 24 px and 4 spp: the noise-floor rule stops it."""
    return write_sphere_fit_case(tmp_path_factory.mktemp("fitcase"), subdivisions=2, size=24, spp=4)


def test_a_fit_interrupted_and_resumed_ends_with_the_uninterrupted_verdict(fit_case, tmp_path, monkeypatch, capsys):
    def args(out: str, *extra: str) -> list[str]:
        return ["fit", str(fit_case / "ref.exr"), "--scene", str(fit_case / "scene.toml"), "--free", "parts.sphere.kd",
                "--out", str(tmp_path / out), "--max-steps", "20", "--quiet", *extra]

    whole = main(args("whole"))
    expected = json.loads((tmp_path / "whole" / "fit.json").read_text())
    update = Checkpoint.update

    def stop_after(self: Checkpoint, entry: dict) -> None:
        update(self, entry)
        if self.steps == STOP_AFTER:
            os.kill(os.getpid(), signal.SIGINT)  # taken at the end of the step, as a Ctrl-C is

    with monkeypatch.context() as m:
        m.setattr(Checkpoint, "update", stop_after)
        assert main(args("stopped")) == 130
    saved = json.loads((tmp_path / "stopped" / "checkpoint.json").read_text())
    assert len(saved["history"]) == STOP_AFTER
    capsys.readouterr()
    assert main(args("stopped", "--resume")) == whole
    got = json.loads((tmp_path / "stopped" / "fit.json").read_text())
    assert (got["status"], got["success"]) == (expected["status"], expected["success"]), (got["history"], expected["history"])
    assert [h["loss"] for h in got["history"][:STOP_AFTER]] == pytest.approx([h["loss"] for h in expected["history"][:STOP_AFTER]], rel=1e-6)
    assert got["steps"] == len(got["history"]) > STOP_AFTER
    assert got["values"]["parts.sphere.kd"] == pytest.approx(expected["values"]["parts.sphere.kd"], abs=0.25 * expected["stderr"]["parts.sphere.kd"])



class Killed(BaseException):
    """Stands for SIGKILL: no clean-up runs (not an Exception, not a KeyboardInterrupt)."""


@pytest.mark.slow
def test_a_fit_killed_at_step_5_resumes_to_the_uninterrupted_verdict_and_exit_code(fit_case, tmp_path, monkeypatch, capsys):
    """Issue 34: killed at its fifth step (or the one before its last, were it shorter) and resumed, a
    fit ended "max steps", exit 3, where the uninterrupted one converged with exit 0. Killed there
    (its checkpoint written, nothing cleaned up) and run with --resume, it ends with the uninterrupted
    fit's status and exit code (0) and its value within 0.25 of its standard error."""
    def args(out: str, *extra: str) -> list[str]:
        return ["fit", str(fit_case / "ref.exr"), "--scene", str(fit_case / "scene.toml"), "--free", "parts.sphere.kd",
                "--start", "parts.sphere.kd=0.05", "--out", str(tmp_path / out), "--max-steps", "12", "--quiet", *extra]

    whole = main(args("whole"))
    expected = json.loads((tmp_path / "whole" / "fit.json").read_text())
    assert whole == 0 and expected["steps"] >= 2, expected["history"]
    kill_at = min(5, expected["steps"] - 1)
    update = Checkpoint.update

    def killed(self: Checkpoint, entry: dict) -> None:
        update(self, entry)
        if self.steps == kill_at:
            raise Killed

    with monkeypatch.context() as m:
        m.setattr(Checkpoint, "update", killed)
        with pytest.raises(Killed):
            main(args("killed"))
    assert len(json.loads((tmp_path / "killed" / "checkpoint.json").read_text())["history"]) == kill_at
    capsys.readouterr()
    assert main(args("killed", "--resume")) == whole
    got = json.loads((tmp_path / "killed" / "fit.json").read_text())
    assert (got["status"], got["success"]) == (expected["status"], expected["success"]), (got["history"], expected["history"])
    assert got["values"]["parts.sphere.kd"] == pytest.approx(expected["values"]["parts.sphere.kd"], abs=0.25 * expected["stderr"]["parts.sphere.kd"])
    assert not (tmp_path / "killed" / "checkpoint.json").exists()
