"""``modaluq compare FIRST SECOND``: two records identified alike and compared against their σ."""

import numpy as np
import pytest

import modaluq
from modaluq.analysis import Analysis
from modaluq.cli import main
from modaluq.simulate import simulate

STIFFNESS = np.array([100.0, 200.0, 100.0, 200.0, 100.0, 200.0])


def _csv(path, seed, stiffness=STIFFNESS):
    sim = simulate(20_000, seed=seed, stiffness=stiffness)
    np.savetxt(path, np.column_stack([np.arange(len(sim.y)) / sim.fs, sim.y]), delimiter=",",
               header="time [s],a,b,c", comments="")
    return path


@pytest.fixture(scope="module")
def files(tmp_path_factory):
    d = tmp_path_factory.mktemp("records")
    softer = STIFFNESS.copy()
    softer[-1] *= 0.9
    return _csv(d / "monday.csv", 1), _csv(d / "tuesday.csv", 2), _csv(d / "softer.csv", 3, softer)


def test_the_report_is_compare_modes_of_the_two_records_identified_alike(files, tmp_path, capsys):
    monday, tuesday, _ = files
    out = tmp_path / "cmp"
    status = main(["compare", str(monday), str(tuesday), "--frequency-range", "1", "20", "--out", str(out),
                   "--no-progress"])
    text, err = capsys.readouterr()
    assert status == 0, err
    # independently: the first as the options say, the second with the settings the first used
    settings = modaluq.Settings(frequency_range=(1.0, 20.0))
    first = Analysis.from_file(monday, settings=settings).run(check_harmonics=False, issue_warnings=False)
    used = first.result.settings
    second = Analysis.from_file(tuesday, settings=settings).with_settings(
        block_rows=used["block_rows"], past_block_rows=used["past_block_rows"], orders=used["orders"],
        n_blocks=used["n_blocks"]).run(check_harmonics=False, issue_warnings=False)
    expected = modaluq.compare_modes(first, second)
    assert text.endswith(expected.report()) and text.startswith(f"# {monday} against {tuesday}")
    assert f"block_rows {used['block_rows']}" in text and "6 modes in both sets" in text
    assert (out / "report.md").read_text(encoding="utf-8") == text
    table = (out / "pairs.csv").read_text().splitlines()
    assert table[0].startswith("frequency_hz_1,frequency_hz_2") and len(table) == 1 + 6


def test_a_softer_spring_shows_and_the_pairing_options_reach_it(files, capsys):
    monday, _, softer = files
    argv = ["compare", str(monday), str(softer), "--frequency-range", "1", "20", "--no-progress"]
    assert main(argv) == 0
    assert "5 modes in both sets" in capsys.readouterr().out  # the 2.8 % move is beyond the 2 % window
    assert main([*argv, "--tolerance", "0.05"]) == 0
    text = capsys.readouterr().out
    assert "6 modes in both sets" in text and "apart by at most 5 %" in text
    assert main([*argv, "--orders", "2:40:2"]) == 0  # --orders reaches both records
    assert "orders 2-40" in capsys.readouterr().out
    assert main([*argv, "--tolerance", "1e-9", "--pair-within-std", "0"]) == 0
    assert "No mode was found in both sets" in capsys.readouterr().out


@pytest.mark.parametrize("extra, message", [
    (["--tolerance", "0"], "--tolerance"),
    (["--pair-within-std", "-1"], "--pair-within-std"),
    (["--block-rows", "1"], "--block-rows"),
    (["--no-uncertainty"], "has no σ"),
])
def test_bad_options_are_named(files, extra, message, capsys):
    monday, tuesday, _ = files
    assert main(["compare", str(monday), str(tuesday), "--no-progress", *extra]) == 2
    err = capsys.readouterr().err
    assert message in err and len(err.strip().splitlines()) == 1


def test_a_missing_file_and_an_out_that_is_a_file_are_named(files, tmp_path, capsys):
    monday, _, _ = files
    assert main(["compare", str(monday), str(tmp_path / "missing.csv"), "--no-progress"]) == 2
    assert "missing.csv" in capsys.readouterr().err
    (tmp_path / "taken").write_text("x")
    assert main(["compare", str(monday), str(monday), "--out", str(tmp_path / "taken"), "--no-progress"]) == 2
    assert "--out must be a directory" in capsys.readouterr().err
