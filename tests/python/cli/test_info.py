"""``modaluq info FILE`` (issue 26, item 11): channels, units, roles, rate, length and the file's
groups, datasets or variables, read as ``modaluq identify`` reads it, without identifying."""

import pathlib

import numpy as np
import pytest

import modaluq.analysis
from modaluq.cli import main

DATA = pathlib.Path(__file__).resolve().parents[4] / "shared" / "data"
if not DATA.is_dir():
    DATA = pathlib.Path("/work/shared/data")


@pytest.fixture(autouse=True)
def nothing_is_identified(monkeypatch):
    def refuse(*args, **kwargs):
        raise AssertionError("modaluq info identified")
    monkeypatch.setattr(modaluq.analysis.Analysis, "run", refuse)
    monkeypatch.setattr(modaluq.analysis, "identify_quietly", refuse)


def info(capsys, *argv):
    status = main(["info", *map(str, argv)])
    out, err = capsys.readouterr()
    return status, out, err


@pytest.mark.parametrize("name,rate,samples,channels", [
    ("cessipy_smartphone_slab.npz", "425.08 Hz", "25291 samples (59.4971 s)", ["phone_Z_vertical  m/s^2  output"]),
    ("cesmd_painter_st_overpass_2016.npz", "200 Hz", "12000 samples (60 s)", ["output", "input"]),
    ("koma_shearframe_sim.npz", "12 Hz", "14400 samples (1200 s)", ["level5_disp"]),
    ("owi_offshore_wind_turbine_tower_2020.tdms", "30 Hz", "18000 samples (600 s)",
     ["group acceleration: 8 channels", "TP_ACC_LAT19_315deg_X  g     output"]),
])
def test_info_on_the_shared_records(capsys, name, rate, samples, channels):
    path = DATA / name
    if not path.exists():
        pytest.skip(f"{name} (shared/data) is not here")
    status, out, err = info(capsys, path)
    assert status == 0, err
    assert f"rate: {rate}" in out and f"length: {samples}" in out
    for text in channels:
        assert text in out
    if name.endswith(".npz"):
        assert "array y: shape (" in out


def test_info_lists_the_groups_of_a_tdms_file_and_reads_the_group_asked_for(capsys):
    path = DATA / "owi_sensor_array_with_ambient_2022.tdms"
    if not path.exists():
        pytest.skip("the sensor-array record (shared/data) is not here")
    status, out, err = info(capsys, path, "--read-option", "group=acceleration")
    assert status == 0, err
    assert "group acceleration: 8 channels" in out and "group ambient: 16 channels" in out
    assert "(--read-option group=acceleration)" in out and "8 outputs, 0 inputs" in out


def test_info_on_csv_needs_the_rate_as_identify_does(tmp_path, capsys):
    path = tmp_path / "run.csv"
    np.savetxt(path, np.random.default_rng(0).standard_normal((500, 2)), delimiter=",",
               header="acc [m/s^2],force [N]", comments="", fmt="%.6g")
    status, out, err = info(capsys, path, "--fs", 100, "--inputs", "force")
    assert status == 0, err
    assert "rate: 100 Hz" in out and "length: 500 samples (5 s)" in out
    assert "acc    m/s^2  output" in out and "force  N      input" in out


def test_info_lists_an_hdf5_file_it_cannot_read_as_is_then_fails_in_one_line(tmp_path, capsys):
    h5py = pytest.importorskip("h5py")
    path = tmp_path / "daq.h5"
    with h5py.File(path, "w") as f:
        f.create_dataset("run1/acc", data=np.zeros((400, 3)) + np.arange(400.0)[:, None]).attrs["fs"] = 50.0
        f.create_dataset("run2/acc", data=np.ones((300, 2)) + np.arange(300.0)[:, None]).attrs["fs"] = 50.0
    status, out, err = info(capsys, path)
    assert "group /run1: 1 members" in out and "dataset /run2/acc: shape (300, 2), float64" in out
    if status == 2:  # two 2-D datasets: the reader needs dataset=
        assert err.count("\n") == 1 and "modaluq info: error:" in err
    status, out, err = info(capsys, path, "--read-option", "dataset=/run2/acc")
    assert status == 0, err
    assert "rate: 50 Hz" in out and "length: 300 samples (6 s)" in out and "2 outputs" in out


def test_info_lists_the_variables_of_matlab_files(tmp_path, capsys):
    sio = pytest.importorskip("scipy.io")
    path = tmp_path / "v5.mat"
    sio.savemat(str(path), {"acc": np.random.default_rng(1).standard_normal((600, 3)), "fs": 200.0})
    status, out, err = info(capsys, path, "--read-option", "variable=acc")
    assert status == 0, err
    assert "variable acc: shape (600, 3), double" in out and "rate: 200 Hz" in out and "600 samples (3 s)" in out

    h5py = pytest.importorskip("h5py")
    path = tmp_path / "v73.mat"
    with h5py.File(path, "w", userblock_size=512) as f:
        f.create_dataset("acc", data=np.random.default_rng(2).standard_normal((3, 800))).attrs["MATLAB_class"] = \
            np.bytes_("double")
        f.create_dataset("Fs", data=np.array([[100.0]])).attrs["MATLAB_class"] = np.bytes_("double")
    status, out, err = info(capsys, path, "--read-option", "variable=acc")
    assert status == 0, err
    assert "variable /acc: shape (3, 800)" in out and "length: 800 samples (8 s)" in out


def test_info_on_a_missing_or_unsupported_file_is_one_line_and_status_2(tmp_path, capsys):
    status, out, err = info(capsys, tmp_path / "absent.npz")
    assert status == 2 and "modaluq info: error:" in err and err.count("\n") == 1
    (tmp_path / "x.xyz").write_text("1,2\n")
    status, out, err = info(capsys, tmp_path / "x.xyz")
    assert status == 2 and "unsupported file extension" in err
