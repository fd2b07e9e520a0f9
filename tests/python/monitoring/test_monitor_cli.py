"""``modaluq monitor``: the command over folders of files, its failures and its output."""

import os
import sys

import pytest

from modaluq.cli import main
from modaluq.monitoring import load_tracks

pytest.importorskip("xarray")


def test_cli_over_a_folder_of_csv_files(csv_folder, tmp_path, capsys):
    folder, _ = csv_folder
    out = tmp_path / "tracks.nc"
    rc = main(["monitor", str(folder), "--out", str(out), "--orders", "2:24:2", "--reference-records", "10",
               "--covariates", str(folder.with_name("site.covariates.csv")), "--plot", str(tmp_path / "f.png"),
               "--threads", "2", "--no-progress", "--n-blocks", "40", "--frequency-range", "1", "20",
               "--block-rows", "12"])
    captured = capsys.readouterr()
    text = captured.out
    assert rc == 0, text
    assert "20 records: 20 identified, 0 failed" in text and out.exists() and (tmp_path / "f.png").exists()
    ds = load_tracks(out)
    assert ds["frequency_hz"].dims == ("record", "mode") and ds["alarm"].dims == ("record", "mode")
    assert ds["alarm"].dtype == bool
    # the records' warnings (lags of 12 rows, 0.24 s, under one period of the band's 1 Hz edge and
    # of mode 1 at 1.95 Hz, which lies near that edge): counted on stderr, kept in the store
    warned = [w for w in ds["warnings"].values if w]
    assert warned and f"{len(warned)} of 20 records have identification warnings" in captured.err


def test_cli_over_only_bad_files_exits_2_with_a_summary(tmp_path, capsys):
    bad = tmp_path / "bad"
    bad.mkdir()
    for k in range(3):
        (bad / f"r{k}.csv").write_text("t,a\n0,nan\n0.02,1\n")
    rc = main(["monitor", str(bad), "--out", str(tmp_path / "t.nc"), "--no-progress"])
    err = capsys.readouterr().err
    assert rc == 2
    assert "3 of 3 records failed (3 at load)" in err and "no record could be identified" in err
    assert err.count("failed: ") == 3
    assert main(["monitor", str(bad), "--out", str(tmp_path / "t.txt")]) == 2
    assert "--out" in capsys.readouterr().err
    # an image type matplotlib cannot write is refused before any record is run
    assert main(["monitor", str(bad), "--out", str(tmp_path / "u.nc"), "--plot", str(tmp_path / "f.xyz")]) == 2
    assert "--plot" in capsys.readouterr().err and not (tmp_path / "u.parts").exists()


def test_cli_whose_reader_stops_reading_exits_0_with_every_file_written(csv_folder, tmp_path, monkeypatch):
    # modaluq monitor ... | head -1: the summary meets a closed pipe after the files are written
    folder, _ = csv_folder
    read_end, write_end = os.pipe()
    os.close(read_end)
    closed = os.fdopen(write_end, "w", buffering=1)
    monkeypatch.setattr(sys, "stdout", closed)
    out = tmp_path / "t.nc"
    rc = main(["monitor", str(folder), "--out", str(out), "--orders", "2:24:2", "--reference-records", "10",
               "--plot", str(tmp_path / "f.png"), "--plot-control-chart", str(tmp_path / "c.png"), "--no-progress"])
    monkeypatch.undo()
    closed.close()
    assert rc == 0 and out.exists() and (tmp_path / "f.png").exists() and (tmp_path / "c.png").exists()
