"""The reduced soak (``tools/soak.py --quick``): kill -9 during a sweep and its rerun, Ctrl-C during a
render, a sweep into a full disk; no data loss, wrong result or crash. ``make soak`` runs the full one."""

from __future__ import annotations

import os
import re
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]


# `make slow` (and `make soak`, the whole soak): the tool as a whole, about a minute of processes. Its three cases are
# each `make test`'s too: sweep-kill in test_sweep.py::test_sweep_killed_half_way_resumes_to_the_uninterrupted_result,
# render-int in test_reliability.py::test_interrupted_render_leaves_nothing_half_written, a full disk's ENOSPC in
# test_locks.py::test_a_write_error_names_the_output_file_not_its_stage (the real tmpfs needs root: skipped without).
@pytest.mark.slow
def test_the_quick_soak_counts_no_data_loss_wrong_result_or_crash(tmp_path):
    run = subprocess.run([sys.executable, str(ROOT / "tools" / "soak.py"), "--quick", "--seed", "1", "--work", str(tmp_path)],
                         capture_output=True, text=True, env={**os.environ, "PYTHONPATH": str(ROOT)}, timeout=600)
    assert run.returncode == 0, run.stdout + run.stderr
    counts = re.search(r"soak: (\d+) cases .*data loss (\d+), wrong results (\d+), crashes (\d+)", run.stdout)
    assert counts, run.stdout
    assert counts.groups() == ("3", "0", "0", "0"), run.stdout
    assert re.findall(r"^\s+\d+ (\S+)\s+(ok|skipped)", run.stdout, flags=re.MULTILINE)[:2] == [("sweep-kill", "ok"), ("render-int", "ok")], run.stdout
