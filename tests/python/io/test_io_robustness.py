"""Regression tests of issue #13: loader failures are ValueErrors naming the file, a crash or
hang of a third-party parser is contained, CSV time units are honoured, truncation is loud."""

from __future__ import annotations

import re
import sys
from pathlib import Path

import numpy as np
import pytest

import modaluq.io as mio
from modaluq.io import load

FS = 100.0


def raises_naming(path, match=""):
    return pytest.raises(ValueError, match=re.escape(Path(path).name) + ".*" + match)


# ============================================================================ 1. CSV time units
@pytest.mark.parametrize("header,scale", [  # scale: seconds per unit
    ("time [min]", 60), ("t (ms)", 1e-3), ("Time_msec", 1e-3), ("time/ns", 1e-9),
    ("time [h]", 3600), ("seconds", 1), ("s", 1), ("time [s]", 1), ("time_ms", 1e-3),
    ("TIME (us)", 1e-6), ("t [sec]", 1), ("time / min", 60), ("Time [minutes]", 60)])
def test_csv_time_units(tmp_path, header, scale):
    p = tmp_path / "u.csv"
    p.write_text(f"{header},a\n" + "\n".join(f"{k / FS / scale:.12g},{k % 3}" for k in range(30)))
    r = load(p)
    assert r.fs == pytest.approx(FS, rel=1e-9)
    assert r.output_names == ("a",)


@pytest.mark.parametrize("header", ["time [furlong]", "t (samples)", "time/ticks"])
def test_csv_unknown_time_unit(tmp_path, header):
    p = tmp_path / "unk.csv"
    p.write_text(f"{header},a\n" + "\n".join(f"{k},{k % 3}" for k in range(30)))
    with raises_naming(p, re.escape(repr(header)) + ".*unknown time unit.*understood: s, ms"):
        load(p)
    assert load(p, fs=10.0).output_names == ("a",)  # an explicit fs makes the unit irrelevant


def test_csv_time_like_names_are_not_time(tmp_path):
    p = tmp_path / "n.csv"
    p.write_text("time_x,a\n" + "\n".join(f"{k},{k % 3}" for k in range(30)))
    assert load(p, fs=5.0).output_names == ("time_x", "a")


# ============================================================================ 2. TDMS truncation
def _tdms_3_segments(path):
    nptdms = pytest.importorskip("nptdms")
    with nptdms.TdmsWriter(str(path)) as w:
        for k in range(3):
            w.write_segment([nptdms.ChannelObject("g", "a", np.arange(100.0) + 100 * k,
                                                  properties={"wf_increment": 1 / FS})])
    raw = path.read_bytes()
    return raw, [m.start() for m in re.finditer(b"TDSm", raw)]


@pytest.mark.parametrize("into", [1, 13, 27, 40])  # inside the lead-in, then the metadata
def test_tdms_cut_in_later_segment_header(tmp_path, into):
    raw, starts = _tdms_3_segments(tmp_path / "full.tdms")
    p = tmp_path / "cut.tdms"
    p.write_bytes(raw[:starts[2] + into])
    with raises_naming(p, "truncated.*segment 2.*200 samples"):
        load(p)


def test_tdms_unfinished_segment(tmp_path):
    raw, starts = _tdms_3_segments(tmp_path / "full.tdms")
    b = bytearray(raw)
    b[starts[2] + 12:starts[2] + 20] = b"\xff" * 8  # LabVIEW's "never finished" length
    p = tmp_path / "unfinished.tdms"
    p.write_bytes(bytes(b))
    with raises_naming(p, "never finished"):
        load(p)


# ============================================================================ 3. crash / hang
def _corrupt_mat(tmp_path):
    sio = pytest.importorskip("scipy.io")
    good = tmp_path / "good.mat"
    sio.savemat(str(good), {"data": np.zeros((100, 2)), "fs": 100.0})
    b = bytearray(good.read_bytes())
    b[176] = 0x7F  # type of the real part of 'data': SciPy indexes a table with it
    p = tmp_path / "crash.mat"
    p.write_bytes(bytes(b))
    return p


def test_mat5_unknown_element_type_rejected_before_scipy(tmp_path):
    p = _corrupt_mat(tmp_path)
    for isolate in (True, False):  # validated in this process: no SciPy call at all
        with raises_naming(p, "byte 176 has unknown type 127"):
            load(p, isolate=isolate)


def test_mat5_dimensions_checked_against_content(tmp_path):
    """A flipped bit in a cell's dimensions made SciPy allocate and loop over 5e8 elements
    (seconds to minutes and gigabytes) before failing; found by tests/fuzz."""
    sio = pytest.importorskip("scipy.io")
    p = tmp_path / "cell.mat"
    sio.savemat(str(p), {"c": np.array([np.ones(2), np.ones(3)], dtype=object)})
    b = bytearray(p.read_bytes())
    assert b[160:168] == bytes([1, 0, 0, 0, 2, 0, 0, 0])  # dims (1, 2) of the cell
    b[167] = 0x20
    p.write_bytes(bytes(b))
    with raises_naming(p, r"dimensions \(1, 536870914\) call for 536870914 elements but it "
                          "holds 2"):
        load(p, isolate=False)


def test_mat5_complex_flag_without_imaginary_part(tmp_path):
    """Setting the complex flag of a real array made SciPy read a missing imaginary part and
    segfault; found by tests/fuzz."""
    p = _corrupt_mat(tmp_path)
    b = bytearray((tmp_path / "good.mat").read_bytes())
    b[145] |= 0x08  # array flags of 'data': complex
    p.write_bytes(bytes(b))
    with raises_naming(p, "imaginary elements but its data holds 0 bytes"):
        load(p, isolate=False)


def test_parser_crash_is_contained(tmp_path):
    from modaluq.io import _common, matlab

    p = _corrupt_mat(tmp_path)
    with raises_naming(p, r"MATLAB parser crashed \(signal 11"):  # validation bypassed
        _common.parse_isolated(True, matlab._load_v5, p, "MATLAB", p)
    assert load(tmp_path / "good.mat").n_samples == 100  # the helper recovers


def _hanging_h5(tmp_path):
    h5py = pytest.importorskip("h5py")
    p = tmp_path / "hang.h5"
    with h5py.File(p, "w") as f:
        d = f.create_dataset("acc", data=np.zeros((100, 2)))
        d.attrs["fs"] = FS
        d.attrs["channel_names"] = ["a1", "a2"]
    raw = bytearray(p.read_bytes())
    i = raw.index(b"GCOL")
    raw[i + 24:i + 32] = bytes(8)  # size of the first global heap object := 0
    p.write_bytes(bytes(raw))
    return p


def test_parser_hang_is_stopped(tmp_path, monkeypatch):
    p = _hanging_h5(tmp_path)
    monkeypatch.setattr(mio, "PARSE_TIMEOUT", 1.5)
    with raises_naming(p, r"HDF5 parser did not finish within 2 s"):
        load(p)


@pytest.mark.skipif(sys.platform == "win32", reason="POSIX signals")
def test_ctrl_c_during_a_parser_hang(tmp_path, monkeypatch):
    import os
    import signal
    import threading
    import time

    p = _hanging_h5(tmp_path)
    monkeypatch.setattr(mio, "PARSE_TIMEOUT", 60.0)
    # A process started in the background by a non-interactive shell inherits SIGINT ignored,
    # and Python then installs no KeyboardInterrupt handler: install it for this test.
    previous = signal.signal(signal.SIGINT, signal.default_int_handler)
    threading.Timer(1.0, os.kill, (os.getpid(), signal.SIGINT)).start()
    t0 = time.monotonic()
    try:
        with pytest.raises(KeyboardInterrupt):
            load(p)
    finally:
        signal.signal(signal.SIGINT, previous)
    assert time.monotonic() - t0 < 20  # not the 60 s limit: Ctrl-C works again
    monkeypatch.setattr(mio, "PARSE_TIMEOUT", 0.5)
    with raises_naming(p, "did not finish"):  # a fresh helper after the killed one
        load(p)


def test_isolation_switch(tmp_path):
    h5py = pytest.importorskip("h5py")
    p = tmp_path / "ok.h5"
    with h5py.File(p, "w") as f:
        f.create_dataset("acc", data=np.arange(20.0).reshape(10, 2)).attrs["fs"] = FS
    a, b = load(p), load(p, isolate=False)
    np.testing.assert_array_equal(a.y, b.y)
    assert a.fs == b.fs == FS
    with pytest.raises(TypeError, match="isolate"):
        load(p, isolate="yes")
    with raises_naming(p, "dataset 'nope' not found"):  # errors raised in the child come back
        load(p, dataset="nope")


# ============================================================================ 4. error types
def test_csv_header_with_bare_cr(tmp_path):
    p = tmp_path / "cr.csv"
    p.write_bytes(b"time,a\rb\n0,1\n1,2\n")
    with raises_naming(p):
        load(p)


def test_csv_old_mac_line_endings(tmp_path):
    p = tmp_path / "mac.csv"
    p.write_bytes(b"time,a\r0,1\r0.5,2\r1,3\r")
    assert load(p).fs == 2.0


def test_csv_header_cell_over_128k(tmp_path):
    p = tmp_path / "big.csv"
    p.write_text('time,"' + "a" * 140_000 + '"\n0,1\n1,2\n')
    with raises_naming(p, "header"):
        load(p)


def test_npz_member_not_npy(tmp_path):
    import zipfile

    p = tmp_path / "raw.npz"
    with zipfile.ZipFile(p, "w") as z:
        z.writestr("y.npy", b"hello world")
    with raises_naming(p, "'y' of the archive is not .npy data"):
        load(p, fs=FS)


@pytest.mark.filterwarnings("ignore:overflow:RuntimeWarning", "ignore:invalid:RuntimeWarning")
def test_time_vector_overflow(tmp_path):
    """UFF uneven abscissa near the float limit: was ZeroDivisionError (1 / (1 / inf))."""
    pyuff = pytest.importorskip("pyuff")
    p = tmp_path / "x.uff"
    uf = pyuff.UFF(str(p))
    uf.write_sets(pyuff.prepare_58(
        func_type=1, rsp_node=1, rsp_dir=3, ref_node=1, ref_dir=3, id1="a", data=np.arange(2.0),
        x=np.array([-1e308, 1e308]), abscissa_spacing=0, binary=1, abscissa_spec_data_type=17,
        ordinate_spec_data_type=12, orddenom_spec_data_type=0, rsp_ent_name="s",
        ref_ent_name="s"), mode="add")
    with raises_naming(p):
        load(p)
    from modaluq.io._common import fs_from_time

    for t in ([-1e308, 1e308], [0.0, 5e-324]):
        with raises_naming("f.csv", "no usable sample period"):
            fs_from_time(t, "f.csv")


def test_uff_completeness_check_does_not_copy_the_file(tmp_path, monkeypatch):
    pyuff = pytest.importorskip("pyuff")
    p = tmp_path / "ok.uff"
    uf = pyuff.UFF(str(p))
    uf.write_sets(pyuff.prepare_58(
        func_type=1, rsp_node=1, rsp_dir=3, ref_node=1, ref_dir=3, id1="a",
        data=np.arange(8.0), x=np.arange(8) / FS, abscissa_spacing=1, binary=1,
        abscissa_spec_data_type=17, ordinate_spec_data_type=12, orddenom_spec_data_type=0,
        rsp_ent_name="s", ref_ent_name="s"), mode="add")

    def no_read_bytes(self):
        raise MemoryError  # what a multi-GB file did: read_bytes + slice + strip = 3x its size

    monkeypatch.setattr(Path, "read_bytes", no_read_bytes)
    assert load(p).n_samples == 8


def test_memory_error_in_parser_is_named(tmp_path, monkeypatch):
    pyuff = pytest.importorskip("pyuff")
    p = tmp_path / "m.uff"
    p.write_text("    -1\n    58\n    -1\n")

    def boom(*a, **k):
        raise MemoryError

    monkeypatch.setattr(pyuff, "UFF", boom)
    with raises_naming(p, "MemoryError"):
        load(p)


# ============================================================================ 5. fuzz contract
def test_fuzz_contract():
    """A few hundred mutations per format through the fuzz harness (tests/fuzz)."""
    sys.path.insert(0, str(Path(__file__).resolve().parents[2] / "fuzz"))
    try:
        import fuzz_loaders
    finally:
        sys.path.pop(0)
    res = fuzz_loaders.fuzz(runs=300, seed=2024, hang=10.0, log=lambda m: None)
    assert res, "no format could be fuzzed"
    bad = {fmt: r["failures"] for fmt, r in res.items() if r["failures"]}
    assert not bad, bad
    assert all(r["runs"] == 300 for r in res.values())
