"""Names from a log shown on a terminal: escape sequences and rich markup appear as characters
(issue 37: ``redrive info`` printed ``\\x1b[2J`` from a topic name raw and cleared the screen)."""

from __future__ import annotations

import contextlib
import io
import subprocess
import sys
from pathlib import Path

import numpy as np

from redrive.io.mcap.writer import McapWriter
from redrive.output.text import doc_summary, printable, shown
from redrive.types import Imu

HOSTILE = "/imu\x1b[2J\x1b]0;pwned\x07[bold]x[/]\u2028\\"


def test_printable_escapes_controls_and_backslashes() -> None:
    assert printable("/lidar_top") == "/lidar_top"
    assert printable("a\x1b[2Jb") == "a\\x1b[2Jb"
    assert printable("a\\x1b") == "a\\\\x1b"  # a literal backslash cannot pose as an escape
    assert printable("\u2028\x7f\n") == "\\u2028\\x7f\\n"
    assert shown("[bold]x[/]") == "\\[bold]x\\[/]"


def test_info_prints_a_hostile_topic_name_escaped(tmp_path: Path) -> None:
    log = tmp_path / "hostile.mcap"
    imu = Imu(
        linear_acceleration=np.zeros(3),
        angular_velocity=np.zeros(3),
        orientation=np.array([0.0, 0.0, 0.0, 1.0]),
    )
    with McapWriter(log) as out:
        out.write(HOSTILE, 1_000, imu, frame_id="imu")
    done = subprocess.run(
        [sys.executable, "-m", "redrive", "info", str(log)],
        capture_output=True,
        text=True,
        check=False,
        env={"COLUMNS": "300", "PATH": "/usr/bin:/bin"},
    )
    assert done.returncode == 0, done.stderr
    for raw in ("\x1b", "\x07", "\u2028"):
        assert raw not in done.stdout
    flat = "".join(done.stdout.split())
    assert "/imu\\x1b[2J\\x1b]0;pwned\\x07[bold]x[/]\\u2028\\\\" in flat


def test_doc_summary_is_the_first_paragraph_in_plain_text() -> None:
    doc = """nuPlan ``no_ego_at_fault_collisions``: contacts
        of the ego with   ground-truth boxes (:mod:`redrive.evaluation.closedloop.lanes`,
        :func:`~redrive.motion.comfort_kinematics`).

        The second paragraph is left out."""
    assert doc_summary(doc) == (
        "nuPlan no_ego_at_fault_collisions: contacts of the ego with ground-truth boxes "
        "(redrive.evaluation.closedloop.lanes, redrive.motion.comfort_kinematics)."
    )
    assert doc_summary(None) == ""


def test_redrive_metrics_shows_no_sphinx_markup() -> None:
    from redrive.cli.main import main

    out = io.StringIO()
    with contextlib.redirect_stdout(out):
        assert main(["metrics"]) == 0
    text = out.getvalue()
    assert "at_fault_collisions" in text
    assert "no_ego_at_fault_collisions" in text
    for markup in ("``", ":mod:`", ":func:`", ":class:`"):
        assert markup not in text, markup
