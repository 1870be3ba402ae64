"""The progress display: silent for short work, periodic lines in a log, one final line."""

from __future__ import annotations

from spacefit.progress import Progress


def test_log_gets_periodic_lines_and_a_final_one(capsys):
    progress = Progress("work", delay=0.0, interval=0.0)
    for i in range(1, 4):
        progress(i, 3)
    lines = capsys.readouterr().err.splitlines()
    assert [line.split("] ")[1].split()[0] for line in lines] == ["1/3", "2/3", "3/3"]


def test_log_lines_are_spaced_by_the_interval(capsys):
    progress = Progress("work", delay=0.0, interval=3600.0)
    for i in range(1, 6):
        progress(i, 5)
    lines = capsys.readouterr().err.splitlines()
    assert [line.split("] ")[1].split()[0] for line in lines] == ["1/5", "5/5"]


def test_short_work_is_silent(capsys):
    progress = Progress("work", delay=60.0)
    for i in range(1, 4):
        progress(i, 3)
    assert capsys.readouterr().err == ""


def test_progress_bar_in_a_log_gives_lines_with_time_left(capsys):
    from spacefit.progress import progress_bar

    bar = progress_bar(4, "sweep", initial=1, interval=0.0)  # pytest's stderr is not a terminal
    for _ in range(3):
        bar.update()
    bar.close()
    lines = capsys.readouterr().err.splitlines()
    assert [line.split("] ")[1].split()[0] for line in lines] == ["2/4", "3/4", "4/4"]
    assert "left" in lines[0] and "left" not in lines[-1]
    quiet = progress_bar(4, "sweep", quiet=True)
    quiet.update()
    quiet.close()
    assert capsys.readouterr().err == ""
