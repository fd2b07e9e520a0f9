"""Fixtures of the monitoring tests: a simulated campaign, its serial run, a folder of its files."""

import os

import pytest
from monitoring_support import SETTINGS

from modaluq.monitoring import monitor, simulate_monitoring


@pytest.fixture(scope="module")
def campaign():
    return simulate_monitoring(24, n_samples=6000, seed=11)


@pytest.fixture(scope="module")
def serial(campaign):
    return monitor(campaign.records, settings=SETTINGS, threads=1, progress=False)


@pytest.fixture(scope="module")
def csv_folder(tmp_path_factory):
    folder = tmp_path_factory.mktemp("records") / "site"
    camp = simulate_monitoring(20, n_samples=4000, seed=5)
    camp.write(folder)
    return folder, camp


@pytest.fixture(autouse=True, scope="session")
def records_written_long_ago():
    """The tests write their record files just before they run them: no wait for them to settle
    (worker.SETTLE_SECONDS; test_faults_parts.py tests the wait, setting it itself). Session-wide,
    so that module-scoped fixtures that run monitor() see it too."""
    saved = os.environ.get("MODALUQ_SETTLE_SECONDS")
    os.environ["MODALUQ_SETTLE_SECONDS"] = "0"
    yield
    if saved is None:
        os.environ.pop("MODALUQ_SETTLE_SECONDS", None)
    else:
        os.environ["MODALUQ_SETTLE_SECONDS"] = saved
