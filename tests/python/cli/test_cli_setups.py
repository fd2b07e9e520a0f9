"""``modaluq identify --setups campaign.toml``: the example campaign (examples/campaign) end to end,
and the options that do not apply to a campaign refused by name."""

import csv
import json
import pathlib
import sys

import numpy as np
import pytest

from modaluq.cli import main
from modaluq.simulate.campaign import DECK_DOFS, deck_modes

ROOT = pathlib.Path(__file__).resolve().parents[3]
FAST = ["--block-rows", "15", "--orders", "2:24:2", "--n-blocks", "12", "--no-progress"]


@pytest.fixture(scope="module")
def campaign_file(tmp_path_factory):
    """The committed campaign.toml with its CSV files (examples/campaign/make_campaign.py), setups
    a quarter as long (2-3 minutes each)."""
    sys.path.insert(0, str(ROOT / "examples" / "campaign"))
    try:
        import make_campaign
    finally:
        sys.path.pop(0)
    return make_campaign.write(tmp_path_factory.mktemp("campaign"), duration_scale=0.25)


def mac(a, b):
    return abs(np.vdot(a, b)) ** 2 / (np.vdot(a, a).real * np.vdot(b, b).real)


def test_a_campaign_end_to_end(campaign_file, tmp_path, capsys):
    for module in ("matplotlib", "xarray", "netCDF4", "plotly"):
        pytest.importorskip(module)
    js, table, nc, png, html = (tmp_path / n for n in ("modes.json", "modes.csv", "diagram.nc", "diagram.png",
                                                        "report.html"))
    status = main(["identify", "--setups", str(campaign_file), *FAST, "--out", str(js), "--out", str(table),
                   "--out", str(nc), "--plot", str(png), "--report", str(html)])
    out, err = capsys.readouterr()
    assert status == 0, err
    assert "6 setups at 25 Hz, output-only; references: L3, R8; 24 global DOFs" in out
    assert "6 modes" in out

    # the JSON: the global DOFs (references once, then each setup's channels), modes near the truth
    doc = json.loads(js.read_text())
    dofs = ["L3", "R8", "L1", "L2", "L4", "L5", "L6", "L7", "L8", "L9", "L10", "L11", "L12", "R1", "R2", "R3", "R4",
            "R5", "R6", "R7", "R9", "R10", "R11", "R12"]
    assert doc["input"]["outputs"] == dofs and sorted(dofs) == sorted(DECK_DOFS)
    assert [s["name"] for s in doc["input"]["setups"]][4] == "setup 5 (three roving sensors)"
    assert doc["stamp"]["input_file"]["path"] == str(campaign_file.resolve())
    assert len(doc["stamp"]["setup_files"]) == 6 and all(len(s["sha256"]) == 64 for s in doc["stamp"]["setup_files"])
    f0, _, shapes, _ = deck_modes()
    truth = shapes[[DECK_DOFS.index(d) for d in dofs]]
    modes = doc["modes"]
    assert len(modes) == 6
    # the merge's σ of f and ξ: the σ of each cluster's mean (docs/uq-math.md §13.10), said in the file
    assert doc["clustering"]["clustering"]["cluster_std"] == "mean"
    assert "of the mean over the cluster" in doc["units"]["std"]
    for k, m in enumerate(modes):
        assert list(m["mode_shape"]) == dofs
        assert abs(m["frequency_hz"] / f0[k] - 1) < 0.01
        assert 0 < m["frequency_std"] < 0.02 * f0[k]
        phi = np.array([m["mode_shape"][d]["real"] + 1j * m["mode_shape"][d]["imag"] for d in dofs])
        assert mac(phi, truth[:, k]) > 0.99, (k, mac(phi, truth[:, k]))
        assert all(m["mode_shape"][d]["std_real"] >= 0 for d in dofs)

    # the CSV: one row per mode, a column per global DOF
    rows = list(csv.DictReader(table.read_text().splitlines()))
    assert len(rows) == 6 and all(f"mode_shape_{d}_real" in rows[0] for d in dofs)
    np.testing.assert_allclose([float(r["frequency_hz"]) for r in rows], [m["frequency_hz"] for m in modes])

    # the NetCDF diagram: every pole, the shapes over the global DOFs
    import xarray as xr

    with xr.open_dataset(nc) as ds:
        assert [str(c) for c in ds["channel"].values] == dofs
        assert ds.sizes["pole"] > 6 and ds.sizes["mode"] == 6
        np.testing.assert_allclose(ds["selected_mode_shape_real"].values[:, 0],
                                   [modes[0]["mode_shape"][d]["real"] for d in dofs])

    assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    text = html.read_text()
    assert "modaluq identify --setups campaign.toml" in text and "R12" in text


def test_the_campaign_geometry_gives_uff(campaign_file, tmp_path, capsys):
    pytest.importorskip("pyuff")
    uff = tmp_path / "modes.uff"
    status = main(["identify", "--setups", str(campaign_file), *FAST, "--out", str(uff)])
    assert status == 0, capsys.readouterr().err
    assert uff.stat().st_size > 0 and (tmp_path / "modes.std.uff").exists()


@pytest.mark.parametrize("extra,match", [
    (["--outputs", "L1"], "--outputs does not apply with --setups"),
    (["--read-option", "time_column=t"], "--read-option does not apply with --setups"),
    (["--check-horizons"], "--check-horizons does not apply with --setups"),
    (["--bootstrap-draws", "50"], "--bootstrap-draws does not apply with --setups"),
    (["--references", "L3", "L9"], r"setup 0 \('setup1.csv'\) lacks the reference channel\(s\) \['L9'\]"),
    (["--fs", "50"], r"setup 0 \('setup1.csv'\) is sampled at 25 Hz but fs = 50 Hz"),
    (["--orders", "2:80:2"], "above what the merge supports"),
])
def test_mistakes_are_one_line_naming_the_setup_or_option(campaign_file, capsys, extra, match):
    import re

    status = main(["identify", "--setups", str(campaign_file), *FAST[:-1], *extra, "--no-progress"])
    err = capsys.readouterr().err
    assert status == 2 and len(err.strip().splitlines()) == 1
    assert re.search(match, err), err


def test_file_and_setups_exclude_each_other(campaign_file, tmp_path, capsys):
    assert main(["identify", "--no-progress"]) == 2
    assert "give a measurement FILE or --setups CAMPAIGN" in capsys.readouterr().err
    assert main(["identify", str(campaign_file), "--setups", str(campaign_file)]) == 2
    assert "argument --setups: not allowed with argument file" in capsys.readouterr().err
    # the setups' files are inputs: never overwritten
    setup1 = campaign_file.parent / "setup1.csv"
    assert main(["identify", "--setups", str(campaign_file), *FAST, "--out", str(setup1), "--overwrite"]) == 2
    assert f"--out {setup1} is the input file" in capsys.readouterr().err


def test_the_files_settings_are_named_as_written_and_geometry_is_replaced(campaign_file, tmp_path, capsys):
    bad = tmp_path / "bad.toml"
    bad.write_text(campaign_file.read_text().replace("block_rows = 20", "block_rows = 1"))
    for name in [f"setup{j}.csv" for j in range(1, 7)]:
        (tmp_path / name).symlink_to(campaign_file.parent / name)
    assert main(["identify", "--setups", str(bad), "--no-progress"]) == 2
    err = capsys.readouterr().err
    assert f"{bad}: [settings]: block_rows" in err and "--block-rows" not in err
    # --geometry replaces the campaign's: a geometry without R12 is refused before the identification
    geo = tmp_path / "geo.toml"
    geo.write_text((ROOT / "examples/geometry/deck_campaign.toml").read_text().replace('name = "R12"', 'name = "R13"'))
    assert main(["identify", "--setups", str(campaign_file), *FAST, "--geometry", str(geo)]) == 2
    err = capsys.readouterr().err
    assert f"geometry {geo}:" in err and "R12" in err


def test_an_input_output_campaign_file_end_to_end(tmp_path, capsys):
    """A campaign file with ``inputs``: each setup's CSV holds the measured force F5 as its last
    column; the merge is input/output and the modes are those of the deck."""
    from modaluq.simulate.campaign import DEFAULT_DURATIONS, simulate_campaign

    camp = simulate_campaign(5, durations=tuple(d / 4 for d in DEFAULT_DURATIONS), input_dofs=("L5",),
                             input_std=1.0, unknown_input_std=0.3)
    entries = []
    for j, s in enumerate(camp.setups):
        path = tmp_path / f"setup{j + 1}.csv"
        names = list(s.channels) + ["F5"]
        np.savetxt(path, np.column_stack([np.arange(len(s.y)) / camp.fs, s.y, s.u]), delimiter=",",
                   header=",".join(["time [s]"] + names), comments="", fmt="%.6g")
        entries.append(f'[[setup]]\nfile = "{path.name}"\n')
    toml = tmp_path / "campaign.toml"
    toml.write_text('references = ["L3", "R8"]\ninputs = ["F5"]\nfs = 25.0\n\n' + "\n".join(entries))
    js = tmp_path / "modes.json"
    status = main(["identify", "--setups", str(toml), *FAST, "--out", str(js)])
    out, err = capsys.readouterr()
    assert status == 0, err
    assert "6 setups at 25 Hz, input/output" in out and "inputs: F5" in out
    doc = json.loads(js.read_text())
    assert doc["input"]["inputs"] == ["F5"] and "F5" not in doc["input"]["outputs"]
    f0 = camp.frequency_hz
    found = sorted(m["frequency_hz"] for m in doc["modes"])
    assert len(found) == 6 and all(abs(f / t - 1) < 0.01 for f, t in zip(found, f0))
    assert all(0 < m["frequency_std"] < 0.02 * m["frequency_hz"] for m in doc["modes"])
