"""A batch's progress on stderr: the bar's notes (a first run's compile), JSON lines."""

import io

from rtmesh.batch.progress import BatchProgress, JsonProgress


class _Terminal(io.StringIO):
    def isatty(self):
        return True


def test_the_bar_notes_a_line_on_a_terminal_only_and_json_lines_stay_json():
    terminal, log, lines = _Terminal(), io.StringIO(), io.StringIO()
    BatchProgress(3, 0, stream=terminal).note("a note")
    BatchProgress(3, 0, stream=log).note("a note")  # a log: only the progress lines
    BatchProgress(3, 0, enabled=False, stream=_Terminal()).note("a note")
    JsonProgress(3, 0, lines).note("a note")
    assert terminal.getvalue() == "a note\n" and log.getvalue() == "" and lines.getvalue() == ""
