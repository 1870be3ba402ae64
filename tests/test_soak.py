"""The reduced soak (``tools/soak.py --quick``): kill -9 during a sweep and its rerun, Ctrl-C during a
render, a sweep into a full disk; no data loss, wrong result or crash. ``make soak`` runs the full one."""

from __future__ import annotations

import os
import re
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def test_the_quick_soak_counts_no_data_loss_wrong_result_or_crash(tmp_path):
    run = subprocess.run([sys.executable, str(ROOT / "tools" / "soak.py"), "--quick", "--seed", "1", "--work", str(tmp_path)],
                         capture_output=True, text=True, env={**os.environ, "PYTHONPATH": str(ROOT)}, timeout=600)
    assert run.returncode == 0, run.stdout + run.stderr
    counts = re.search(r"soak: (\d+) cases .*data loss (\d+), wrong results (\d+), crashes (\d+)", run.stdout)
    assert counts, run.stdout
    assert counts.groups() == ("3", "0", "0", "0"), run.stdout
    assert re.findall(r"^\s+\d+ (\S+)\s+(ok|skipped)", run.stdout, flags=re.MULTILINE)[:2] == [("sweep-kill", "ok"), ("render-int", "ok")], run.stdout
