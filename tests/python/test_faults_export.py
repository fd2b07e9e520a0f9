"""Issue 26, items 6 and 10 for ``modaluq identify --out`` (:mod:`modaluq.export`): each report is
written to a temporary and renamed into place, so a failed write (full disk) leaves the previous
file whole, names the file and leaves no temporary; text cells of its CSV cannot run as formulas."""

import errno
import json
from pathlib import Path

import pandas as pd
import pytest

import modaluq
from modaluq import export


@pytest.fixture(scope="module")
def identified():
    sim = modaluq.simulate(4000, seed=2)
    diagram = modaluq.identify(sim.y, sim.u, fs=sim.fs, block_rows=15, orders=range(2, 21, 2)).stabilization_diagram()
    return diagram, diagram.select_modes()


def leftovers(folder: Path) -> list:
    return sorted(p.name for p in folder.iterdir() if ".tmp-" in p.name)


@pytest.mark.parametrize("name", ["modes.json", "modes.csv", "modes.nc"])
def test_a_full_disk_leaves_the_previous_report_whole_and_names_the_file(identified, tmp_path, monkeypatch, name):
    if name.endswith(".nc"):
        pytest.importorskip("xarray")
        pytest.importorskip("netCDF4")
    diagram, selected = identified
    path = tmp_path / name
    export.write(path, diagram, selected)
    before = path.read_bytes()

    def half_then_full(target, *args, **kwargs):  # some bytes written, then the disk is full
        Path(target).write_bytes(before[: len(before) // 2])
        raise OSError(errno.ENOSPC, "No space left on device")

    if name.endswith(".json"):
        monkeypatch.setattr(Path, "write_text", lambda self, *a, **k: half_then_full(self))
    elif name.endswith(".csv"):
        monkeypatch.setattr(pd.DataFrame, "to_csv", lambda self, target, *a, **k: half_then_full(target))
    else:
        import xarray as xr

        monkeypatch.setattr(xr.Dataset, "to_netcdf", lambda self, target, *a, **k: half_then_full(target))
    with pytest.raises(OSError, match="No space left") as info:
        export.write(path, diagram, selected)
    assert str(path) in str(info.value) and info.value.errno == errno.ENOSPC
    monkeypatch.undo()
    assert path.read_bytes() == before
    assert leftovers(tmp_path) == []
    if name.endswith(".json"):
        json.loads(path.read_text())


def test_a_missing_folder_is_still_a_file_not_found_error_naming_the_file(identified, tmp_path):
    diagram, selected = identified
    with pytest.raises(FileNotFoundError, match="nowhere"):
        export.write(tmp_path / "nowhere" / "modes.json", diagram, selected)


def test_the_modes_csv_escapes_formulas_and_keeps_negative_numbers(tmp_path):
    class Selected:  # what write_csv reads of SelectedModes
        @staticmethod
        def to_dataframe():
            return pd.DataFrame({"label": ["=1+1", "-x", "ok"], "value": [-0.5, 1.0, 2.0]},
                                index=pd.Index([1, 2, 3], name="mode"))

    text = export.write_csv(tmp_path / "m.csv", Selected()).read_text()
    assert text.splitlines() == ["mode,label,value", "1,'=1+1,-0.5", "2,'-x,1.0", "3,ok,2.0"]
