import os
import sys

import numpy as np
import pytest

sys.path.insert(0, os.path.dirname(__file__))


@pytest.fixture(scope="session")
def chain():
    """The paper's 6-DOF chain, 6,000 samples (3 outputs, 1 known input), seed 3."""
    import modaluq

    return modaluq.simulate(6_000, seed=3)


@pytest.fixture(scope="session")
def chain_10k():
    import modaluq

    return modaluq.simulate(10_000, seed=11)


def relative_error(a, b):
    a, b = np.asarray(a), np.asarray(b)
    return float(np.max(np.abs(a - b) / np.maximum(np.abs(b), 1e-300)))


@pytest.fixture()
def one_line_error(capsys):
    """``check(status)``: a command failed with status 2 and a one-line message (no traceback); returns it."""

    def check(status):
        _, err = capsys.readouterr()
        assert status == 2, err
        lines = err.strip().splitlines()
        assert len(lines) == 1 and "Traceback" not in err, err
        return lines[0]

    return check
