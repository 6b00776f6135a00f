"""The step panel's progress bar (offscreen): a finished run does not end on "0 %" beside the
previous step's words (cvg-bias ended at 0 % with "turn-on 2 / 2" after its estimate step)."""

from __future__ import annotations

import pytest

pytest.importorskip("pytestqt")

from bench.gui.panels import StepList  # noqa: E402


def test_a_done_step_is_full_and_a_new_step_starts_empty_without_the_last_ones_words(qtbot):
    steps = StepList()
    qtbot.addWidget(steps)
    steps.set_steps(("records", "estimate"))
    steps.set_status("records", "running")
    steps.set_progress(0.5, "turn-on 2 / 2")
    steps.set_status("records", "done")
    assert steps.progress.value() == steps.progress.maximum()
    steps.set_status("estimate", "running")  # reports no progress of its own
    assert steps.progress.value() == 0 and steps.message.text() == ""
    steps.set_status("estimate", "done")
    assert steps.progress.value() == steps.progress.maximum()
    steps.set_status("estimate", "error")  # an ERROR keeps where it stood
    assert steps.progress.value() == steps.progress.maximum()
