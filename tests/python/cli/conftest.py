"""Shared checks of the command-line tests."""

import pytest


@pytest.fixture()
def one_line_error(capsys):
    """``check(status)``: the command failed with status 2 and a one-line message (no traceback); returns it."""

    def check(status):
        _, err = capsys.readouterr()
        assert status == 2, err
        lines = err.strip().splitlines()
        assert len(lines) == 1 and "Traceback" not in err, err
        return lines[0]

    return check
