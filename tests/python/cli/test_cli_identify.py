"""``modaluq identify``: order parsing, the whole run on a CSV file, reports, and one-line errors."""

import csv
import hashlib
import json
import os
import subprocess
import sys

import numpy as np
import pytest

import modaluq
from modaluq.cli import main
from modaluq.cli.identify import parse_orders

HEADER = ["time [s]", "acc1 [m/s^2]", "acc2 [m/s^2]", "acc5 [m/s^2]", "force [N]"]


def write_chain_csv(path, sim, n_rows=None):
    """The chain as CSV: a header row, a time column, outputs, then the input force."""
    n = sim.n_samples if n_rows is None else n_rows
    t = np.arange(n) / sim.fs
    data = np.column_stack([t, sim.y[:n], sim.u[:n]])
    np.savetxt(path, data, delimiter=",", header=",".join(HEADER), comments="", fmt="%.10g")
    return path


@pytest.fixture(scope="module")
def chain_csv(tmp_path_factory):
    sim = modaluq.simulate(100_000, seed=1)
    return sim, write_chain_csv(tmp_path_factory.mktemp("cli") / "chain.csv", sim)


# --------------------------------------------------------------------------- --orders


@pytest.mark.parametrize("text,expected", [
    ("2:10:2", [2, 4, 6, 8, 10]), ("2:9:3", [2, 5, 8]), ("3:6", [3, 4, 5, 6]), ("12", [12]),
    ("4, 8,12", [4, 8, 12]), ("12,4,4", [4, 12]), (" 2:4 ", [2, 3, 4]),
])
def test_parse_orders(text, expected):
    assert parse_orders(text) == expected


@pytest.mark.parametrize("text,match", [
    ("", "empty"), ("a", "not an integer"), ("10:2", "below"), ("2:10:0", "step"), ("0", ">= 1"),
    ("1:2:3:4", "a:b or a:b:step"), ("2:x", "'x' is not an integer"),
])
def test_parse_orders_errors_name_the_option(text, match):
    with pytest.raises(ValueError, match=match) as info:
        parse_orders(text)
    assert "--orders" in str(info.value)


def test_parse_read_options():
    from modaluq.cli.identify import parse_read_options

    assert parse_read_options(["dataset=/daq/acc", "transpose=true", "records=[0, 2]", "fs_hint=2.5"]) == {
        "dataset": "/daq/acc", "transpose": True, "records": [0, 2], "fs_hint": 2.5}
    assert parse_read_options(None) == {}


# --------------------------------------------------------------------------- end to end


def test_identify_csv_end_to_end(chain_csv, tmp_path, capsys):
    for module in ("matplotlib", "pandas", "xarray", "netCDF4"):   # extras plot and export
        pytest.importorskip(module)
    sim, path = chain_csv
    png, js, table, nc = (tmp_path / n for n in ("diagram.png", "modes.json", "modes.csv", "diagram.nc"))
    status = main(["identify", str(path), "--inputs", "force", "--block-rows", "25", "--orders", "2:60:2",
                   "--plot", str(png), "--out", str(js), "--out", str(table), "--out", str(nc), "--no-progress"])
    out, err = capsys.readouterr()
    assert status == 0, err
    assert "6 modes" in out and "std f" in out and "input/output" in out

    # the plot is a real PNG image
    assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    import matplotlib.pyplot as plt

    img = plt.imread(png)
    assert img.ndim == 3 and img.shape[0] > 0 and img.shape[1] > 0

    # JSON: stamp and six modes with σ
    report = json.loads(js.read_text())
    stamp = report["stamp"]
    assert stamp["modaluq_version"] == modaluq.__version__
    assert stamp["input_file"]["sha256"] == hashlib.sha256(path.read_bytes()).hexdigest()
    assert stamp["created_utc"].endswith("+00:00")
    ident = stamp["settings"]["identification"]
    assert ident["block_rows"] == 25 and ident["orders"] == list(range(2, 61, 2)) and ident["n_blocks"] == 50
    assert stamp["settings"]["channels"] == {"outputs": ["acc1", "acc2", "acc5"], "inputs": ["force"],
                                             "references": ["acc1", "acc2", "acc5"]}
    assert {"max_frequency_change", "min_mac", "frequency_std_factor"} <= set(stamp["settings"]["stability"])
    modes = report["modes"]
    assert len(modes) == 6
    f = np.array([m["frequency_hz"] for m in modes])
    sf = np.array([m["frequency_std"] for m in modes])
    assert np.all(sf > 0) and all(m["damping_std"] > 0 and m["frequency_spread"] >= 0 for m in modes)
    assert np.all(np.abs(f - sim.frequency_hz) <= 3 * sf)
    assert set(modes[0]["mode_shape"]) == {"acc1", "acc2", "acc5"}
    assert {"real", "imag", "std_real", "std_imag", "spread_real"} <= set(modes[0]["mode_shape"]["acc1"])

    # CSV: the same six modes with σ
    with open(table, newline="") as fh:
        rows = list(csv.DictReader(fh))
    assert len(rows) == 6
    np.testing.assert_allclose([float(r["frequency_hz"]) for r in rows], f, rtol=1e-12)
    np.testing.assert_allclose([float(r["frequency_std"]) for r in rows], sf, rtol=1e-12)

    # NetCDF: the full diagram
    import xarray as xr

    with xr.open_dataset(nc) as ds:
        assert ds.sizes["pole"] == report["diagram"]["n_poles"] and ds.sizes["mode"] == 6
        assert set(ds["status"].values.astype(str)) <= {"stable", "stable_frequency", "unstable", "rejected"}
        assert json.loads(ds.attrs["stamp"])["input_file"]["sha256"] == stamp["input_file"]["sha256"]


def test_identify_csv_output_only(chain_csv, capsys):
    _, path = chain_csv
    status = main(["identify", str(path), "--outputs", "acc1", "acc2", "acc5", "--block-rows", "25",
                   "--orders", "2:60:2", "--no-progress"])
    out, err = capsys.readouterr()
    assert status == 0, err
    assert "output-only" in out and "6 modes" in out


# --------------------------------------------------------------------------- errors


def test_nan_in_csv_is_one_line_naming_row_and_column(tmp_path):
    sim = modaluq.simulate(2_000, seed=4)
    path = write_chain_csv(tmp_path / "bad.csv", sim)
    lines = path.read_text().splitlines()
    data_row = 57                                    # 0-based data row -> file line data_row + 2
    cells = lines[data_row + 1].split(",")
    cells[2] = "nan"                                  # column 'acc2'
    lines[data_row + 1] = ",".join(cells)
    path.write_text("\n".join(lines) + "\n")
    proc = subprocess.run([sys.executable, "-m", "modaluq.cli", "identify", str(path), "--inputs", "force"],
                          capture_output=True, text=True, timeout=120, env={**os.environ, "PYTHONWARNINGS": "ignore"})
    assert proc.returncode == 2
    err = proc.stderr.strip().splitlines()
    assert len(err) == 1, proc.stderr
    assert "Traceback" not in proc.stderr
    assert f"line {data_row + 2}" in err[0] and "'acc2'" in err[0] and "NaN" in err[0]


@pytest.mark.parametrize("argv,match", [
    (["--inputs", "hammer"], "--inputs: channel 'hammer' not found"),
    (["--orders", "2:x"], "--orders"),
    (["--out", "modes.xlsx"], "--out modes.xlsx: unsupported extension"),
    (["--inputs", "force", "--references", "force"], "--references: channel 'force' not found"),
    (["--inputs", "force", "--outputs", "force"], "both select channel 'force'"),
    (["--min-mac", "1.5"], "--min-mac must be <= 1"),
    (["--block-rows", "5", "--orders", "2:60:2"], "order 60"),
    (["--read-option", "bogus=1"], "bogus"),
    (["--read-option", "novalue"], "--read-option 'novalue': expected KEY=VALUE"),
])
def test_bad_arguments_give_one_line_and_status_2(chain_csv, argv, match, capsys, tmp_path, monkeypatch):
    _, path = chain_csv
    monkeypatch.chdir(tmp_path)
    status = main(["identify", str(path), "--no-progress"] + argv)
    out, err = capsys.readouterr()
    assert status == 2
    assert len(err.strip().splitlines()) == 1 and err.startswith("modaluq identify: error: ")
    assert match in err


def test_missing_file_is_one_line(capsys, tmp_path):
    assert main(["identify", str(tmp_path / "nothere.csv")]) == 2
    err = capsys.readouterr().err
    assert len(err.strip().splitlines()) == 1 and "no such file" in err


# --------------------------------------------------------------------------- issue #13: outputs never destroy data



def _sha256(path):
    return hashlib.sha256(path.read_bytes()).hexdigest()


@pytest.fixture()
def small_csv(tmp_path):
    return write_chain_csv(tmp_path / "rec.csv", modaluq.simulate(20_000, seed=5))


FAST_ARGS = ["--inputs", "force", "--block-rows", "10", "--orders", "2:16:2", "--n-blocks", "20", "--no-progress"]


@pytest.mark.parametrize("option,spelling", [
    ("--out", "rec.csv"), ("--out", "./rec.csv"), ("--out", "sub/../rec.csv"), ("--plot", "rec.csv"),
    ("--plot-shapes", "rec.csv"), ("--out", "link.csv"),
])
@pytest.mark.parametrize("overwrite", [[], ["--overwrite"]])
def test_the_input_file_is_never_overwritten(small_csv, monkeypatch, one_line_error, option, spelling, overwrite):
    monkeypatch.chdir(small_csv.parent)
    (small_csv.parent / "sub").mkdir()
    os.symlink(small_csv, small_csv.parent / "link.csv")
    before = _sha256(small_csv)
    err = one_line_error(main(["identify", "rec.csv", option, spelling, *FAST_ARGS, *overwrite]))
    assert err == f"modaluq identify: error: {option} {spelling} is the input file rec.csv; refusing to overwrite it"
    assert _sha256(small_csv) == before


def test_hard_linked_input_is_recognised(small_csv, one_line_error):
    link = small_csv.parent / "same.csv"
    os.link(small_csv, link)
    err = one_line_error(main(["identify", str(small_csv), "--out", str(link), "--overwrite", *FAST_ARGS]))
    assert "is the input file" in err


def test_existing_output_needs_overwrite(small_csv, one_line_error):
    out = small_csv.parent / "modes.json"
    out.write_text("an earlier report\n")
    err = one_line_error(main(["identify", str(small_csv), "--out", str(out), *FAST_ARGS]))
    assert err == f"modaluq identify: error: --out {out} exists; pass --overwrite to replace it"
    assert out.read_text() == "an earlier report\n"
    assert main(["identify", str(small_csv), "--out", str(out), "--overwrite", *FAST_ARGS]) == 0
    assert json.loads(out.read_text())["modes"]


def test_existing_plot_needs_overwrite(small_csv, one_line_error):
    pytest.importorskip("matplotlib")
    png = small_csv.parent / "d.png"
    png.write_bytes(b"old")
    err = one_line_error(main(["identify", str(small_csv), "--plot", str(png), *FAST_ARGS]))
    assert f"--plot {png} exists; pass --overwrite" in err
    assert png.read_bytes() == b"old"


def test_one_file_for_two_outputs_is_refused(small_csv, one_line_error, monkeypatch):
    monkeypatch.chdir(small_csv.parent)
    err = one_line_error(main(["identify", "rec.csv", "--out", "m.json", "--out", "./m.json", *FAST_ARGS]))
    assert err.endswith("--out ./m.json is also the file of --out m.json")
    assert not (small_csv.parent / "m.json").exists()


def test_validate_refuses_to_overwrite_an_earlier_run(tmp_path, one_line_error):
    out = tmp_path / "mc"
    out.mkdir()
    (out / "report.md").write_text("earlier\n")
    argv = ["validate", "--records", "2", "--samples", "3000", "--processes", "1", "--no-progress", "--out", str(out)]
    err = one_line_error(main(argv))
    assert f"--out {out / 'report.md'} exists; pass --overwrite" in err
    assert (out / "report.md").read_text() == "earlier\n"


# --------------------------------------------------------------------------- issue #13: ranges before expansion


@pytest.mark.parametrize("spec", ["1:1000000000000", "2:100000000:2", "99999999999999999999999", "2,4,1000000"])
def test_orders_out_of_range_are_refused_at_once_with_the_largest_possible(small_csv, one_line_error, spec):
    import time

    t0 = time.perf_counter()
    status = main(["identify", str(small_csv), "--inputs", "force", "--block-rows", "10", "--orders", spec,
                   "--no-progress"])
    err = one_line_error(status)
    assert time.perf_counter() - t0 < 10
    # 3 outputs, p = q = 10: min((p-1) l, q r) = min(27, 30)
    assert f"--orders '{spec}': order " in err and "above the largest possible, 27 = min((p-1)·l, q·r)" in err


def test_parse_orders_refuses_before_expanding():
    with pytest.raises(ValueError, match=r"order 1000000000000 is above the largest possible, 100000"):
        parse_orders("1:1000000000000")
    with pytest.raises(ValueError, match=r"order 60 is above the largest possible, 57 because"):
        parse_orders("2:60:2", 57, bound=" because")
    assert parse_orders("2:56:2", 57)[-1] == 56


@pytest.mark.parametrize("argv,match", [
    (["--block-rows", str(2**63)], f"argument --block-rows: must be in [2, 2147483647]; got {2**63}"),
    (["--block-rows", "x"], "argument --block-rows: 'x' is not an integer"),
    (["--past-block-rows", str(10**30)], "argument --past-block-rows: must be in [1, "),
    (["--n-blocks", str(10**18)], "argument --n-blocks: must be in [2, "),
    (["--min-cluster-size", str(2**64)], "argument --min-cluster-size: must be in [1, "),
    (["--dpi", "1e7"], "argument --dpi: must be in (0, 1200]; got 1e7"),
    (["--dpi", "nan"], "argument --dpi: must be in (0, 1200]; got nan"),
    (["--block-rows", "15000"], "--block-rows 15000 with --past-block-rows 15000: p + q = 30000 exceeds the 20000 "
                                "samples of the record"),
])
def test_integer_options_are_capped_naming_the_option(small_csv, one_line_error, argv, match):
    err = one_line_error(main(["identify", str(small_csv), "--inputs", "force", "--no-progress", *argv]))
    assert err.startswith("modaluq identify: error: ") and match in err


@pytest.mark.parametrize("argv,match", [
    (["--processes", str(10**6)], "argument --processes: must be in [1, 256]"),
    (["--records", str(2**63)], "argument --records: must be in [1, "),
    (["--tolerance", "1"], "argument --tolerance: must be in (0, 1); got 1"),
    (["--seed", "-1"], "argument --seed: must be in [0, "),
])
def test_validate_options_are_capped_naming_the_option(one_line_error, argv, match):
    err = one_line_error(main(["validate", "--no-progress", *argv]))
    assert err.startswith("modaluq validate: error: ") and match in err


def test_missing_command_and_bad_demo_option_are_one_line(one_line_error):
    assert one_line_error(main([])) == "modaluq: error: the following arguments are required: COMMAND"
    assert "argument --samples: must be in [1, " in one_line_error(main(["demo", "--samples", "0"]))
    assert one_line_error(main(["identify", "x.csv", "--bogus"])) == \
        "modaluq: error: unrecognized arguments: --bogus"


def test_netcdf_output_without_xarray_is_refused_before_the_work(small_csv, one_line_error, monkeypatch):
    monkeypatch.setitem(sys.modules, "xarray", None)
    nc = small_csv.parent / "d.nc"
    err = one_line_error(main(["identify", str(small_csv), "--out", str(nc), *FAST_ARGS]))
    assert f"--out {nc} needs xarray, which is not installed" in err and 'pip install ".[export]"' in err
    assert not nc.exists()


def test_errors_are_one_line_when_run_as_a_module(small_csv):
    # python -m modaluq.cli: the subcommands raise modaluq.cli's error class, not __main__'s
    proc = subprocess.run([sys.executable, "-m", "modaluq.cli", "identify", str(small_csv), "--out", str(small_csv)],
                          capture_output=True, text=True, timeout=120)
    assert proc.returncode == 2
    assert proc.stderr.strip().splitlines() == [
        f"modaluq identify: error: --out {small_csv} is the input file {small_csv}; refusing to overwrite it"]


def test_cli_check_horizons_prints_the_spread_and_writes_it_to_json(tmp_path, capsys):
    import json

    sim = modaluq.simulate(30_000, seed=2)
    path = tmp_path / "rec.npz"
    np.savez(path, y=sim.y, u=sim.u, fs=sim.fs)
    out = tmp_path / "modes.json"
    assert main(["identify", str(path), "--frequency-range", "1", "20", "--check-horizons", "--no-progress",
                 "--out", str(out)]) == 0
    text = capsys.readouterr().out
    assert "settings check: block_rows 75, 100, 150" in text and "(spread: across the horizons)" in text
    check = json.loads(out.read_text())["horizon_check"]
    assert check["block_rows"] == [75, 100, 150]
    assert len(check["modes"]) == 6 and all(len(m["frequency_hz"]) == 3 for m in check["modes"])


def test_bootstrap_draws_reaches_the_identification(small_csv):
    # docs/uq-math.md §5.6: the option is the library's, recorded with the settings
    out = small_csv.parent / "modes.json"
    assert main(["identify", str(small_csv), "--out", str(out), "--bootstrap-draws", "10", *FAST_ARGS]) == 0
    report = json.loads(out.read_text())
    assert report["stamp"]["settings"]["identification"]["bootstrap_draws"] == 10


@pytest.mark.parametrize("option, key", [("--no-order-discrepancy", "order_discrepancy"),
                                         ("--no-drop-noise-twins", "drop_noise_twins"),
                                         ("--no-reassign-borrowed-poles", "reassign_borrowed_poles")])
def test_a_clustering_switch_reaches_the_selection(small_csv, option, key):
    # docs/settings.md: the clustering option, recorded with the selected modes
    out = small_csv.parent / "modes.json"
    assert main(["identify", str(small_csv), "--out", str(out), option, *FAST_ARGS]) == 0
    assert json.loads(out.read_text())["clustering"]["clustering"][key] is False
    assert main(["identify", str(small_csv), "--out", str(out), "--overwrite", *FAST_ARGS]) == 0
    assert json.loads(out.read_text())["clustering"]["clustering"][key] is True


def test_the_unanchored_switch_reaches_the_selection(small_csv):
    # docs/settings.md: --no-unanchored-sigma is unanchored_noise_coupling None, recorded with the modes
    out = small_csv.parent / "modes.json"
    assert main(["identify", str(small_csv), "--out", str(out), "--no-unanchored-sigma", *FAST_ARGS]) == 0
    assert json.loads(out.read_text())["clustering"]["clustering"]["unanchored_noise_coupling"] is None
    assert main(["identify", str(small_csv), "--out", str(out), "--overwrite", *FAST_ARGS]) == 0
    assert json.loads(out.read_text())["clustering"]["clustering"]["unanchored_noise_coupling"] == 2.0
