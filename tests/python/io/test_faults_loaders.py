"""Issue 26, items 2, 4 and 9 (parser time): the HDF5 and MATLAB v7.3 loaders read only the file
they are given, refuse datasets never written or larger than the file can hold, and stop a
looping parser on a small file within seconds."""

from __future__ import annotations

import re
import subprocess
import sys
import textwrap
import time
from pathlib import Path

import numpy as np
import pytest

import modaluq.io as mio
from memory_probe import PROBE
from modaluq.io import _common, hdf5, read_hdf5, read_matlab

h5py = pytest.importorskip("h5py")

FS = 100.0
#: Bytes another file holds: a loader that follows a link out of the file would return them.
SECRET = np.arange(1000, 1100, dtype=np.float64)


def raises_naming(path, *parts):
    """ValueError whose message names the file and then each of ``parts`` (in order)."""
    return pytest.raises(ValueError, match=re.escape(Path(path).name) + "".join(
        ".*" + re.escape(s) for s in parts))


def _mat73(path):
    """Give an HDF5 file made with ``userblock_size=512`` a MATLAB v7.3 header."""
    head = b"MATLAB 7.3 MAT-file, Platform: GLNXA64, Created on: Mon Jan  1 00:00:00 2024 HDF5 schema 1.00 ."
    with open(path, "r+b") as fh:
        fh.write(head.ljust(116, b" ") + b"\x00" * 8 + b"\x00\x02" + b"IM")
    return path


def _other_files(tmp_path):
    raw = tmp_path / "secret.bin"
    raw.write_bytes(SECRET.tobytes())
    other = tmp_path / "other.h5"
    with h5py.File(other, "w") as f:
        f.create_dataset("data", data=SECRET)
        f.create_group("grp").create_dataset("data", data=SECRET)
    return raw, other


def _pointing_elsewhere(tmp_path, kind, *, mat=False, target=None):
    """A file whose dataset ``acc`` (a MATLAB variable when ``mat``) gets its samples from
    another file: ``kind`` is external raw storage, a virtual dataset, an external link or a
    soft link through an external link."""
    raw, other = _other_files(tmp_path)
    p = tmp_path / (f"{kind}.mat" if mat else f"{kind}.h5")
    with h5py.File(p, "w", **({"userblock_size": 512} if mat else {})) as f:
        f.create_dataset("fs", data=np.array([[FS]]))
        if kind == "external":
            d = f.create_dataset("acc", shape=SECRET.shape, dtype="f8",
                                 external=[(str(target or raw), 0, SECRET.nbytes)])
        elif kind == "virtual":
            layout = h5py.VirtualLayout(shape=SECRET.shape, dtype="f8")
            layout[:] = h5py.VirtualSource(str(other), "data", shape=SECRET.shape)
            d = f.create_virtual_dataset("acc", layout)
        elif kind == "external_link":
            f["acc"] = h5py.ExternalLink(str(other), "/data")
            d = None
        elif kind == "soft_through_external":
            f["outside"] = h5py.ExternalLink(str(other), "/grp")
            f["acc"] = h5py.SoftLink("/outside/data")
            d = None
        else:
            raise AssertionError(kind)
        if mat:
            f["fs"].attrs["MATLAB_class"] = np.bytes_("double")
            if d is not None:
                d.attrs["MATLAB_class"] = np.bytes_("double")
        elif d is not None:
            d.attrs["fs"] = FS
    return _mat73(p) if mat else p


KINDS = ["external", "virtual", "external_link", "soft_through_external"]


# ============================================================================ item 4: other files
@pytest.mark.parametrize("isolate", [True, False])
@pytest.mark.parametrize("kind", KINDS)
def test_hdf5_refuses_data_from_another_file(tmp_path, kind, isolate):
    p = _pointing_elsewhere(tmp_path, kind)
    what = {"external": "external storage", "virtual": "virtual dataset",
            "external_link": "external link", "soft_through_external": "external link"}[kind]
    with raises_naming(p, "acc" if kind != "soft_through_external" else "outside", what):
        read_hdf5(p, dataset="acc", fs=FS, isolate=isolate)
    with raises_naming(p, what):  # the same through load(), fs from the file
        mio.load(p, dataset="/acc")


@pytest.mark.parametrize("kind", KINDS)
def test_hdf5_allow_external_opts_in(tmp_path, kind):
    p = _pointing_elsewhere(tmp_path, kind)
    rec = read_hdf5(p, dataset="acc", fs=FS, allow_external=True)
    np.testing.assert_array_equal(rec.y[:, 0], SECRET)  # documented opt-in: the other file
    with pytest.raises(TypeError, match="allow_external"):
        read_hdf5(p, dataset="acc", fs=FS, allow_external="yes")


def test_hdf5_external_storage_on_dev_zero(tmp_path):
    if not Path("/dev/zero").exists():
        pytest.skip("no /dev/zero")
    p = _pointing_elsewhere(tmp_path, "external", target="/dev/zero")
    with raises_naming(p, "acc", "/dev/zero", "refused"):
        read_hdf5(p, fs=FS)  # also when the dataset is found automatically


@pytest.mark.parametrize("kind", KINDS)
def test_mat73_refuses_data_from_another_file(tmp_path, kind):
    p = _pointing_elsewhere(tmp_path, kind, mat=True)
    for isolate in (True, False):
        with raises_naming(p, "refused"):
            read_matlab(p, variable="acc", isolate=isolate)
    rec = read_matlab(p, variable="acc", allow_external=True)
    np.testing.assert_array_equal(rec.y[:, 0], SECRET)


def test_soft_links_inside_the_file_still_work(tmp_path):
    p = tmp_path / "soft.h5"
    y = np.arange(40.0).reshape(20, 2)
    with h5py.File(p, "w") as f:
        f.create_dataset("raw/acc", data=y).attrs["fs"] = FS
        f["latest"] = h5py.SoftLink("/raw")
        f["loop"] = h5py.SoftLink("/loop")
    np.testing.assert_array_equal(read_hdf5(p, dataset="latest/acc").y, y)
    with raises_naming(p, "loop", "soft links"):
        read_hdf5(p, dataset="loop", fs=FS)
    with raises_naming(p, "'latest/nope' not found"):
        read_hdf5(p, dataset="latest/nope", fs=FS)


# ============================================================================ item 2: unwritten data
def _partly_written(path, *, fillvalue=None, mat=False):
    with h5py.File(path, "w", **({"userblock_size": 512} if mat else {})) as f:
        kw = {} if fillvalue is None else {"fillvalue": fillvalue}
        shape = (3, 60000) if mat else (60000, 3)  # MATLAB: HDF5 shape reversed
        d = f.create_dataset("acc", shape=shape, dtype="f8",
                             chunks=(3, 1000) if mat else (1000, 3), **kw)
        rows = np.random.default_rng(0).standard_normal((40000, 3))
        if mat:
            d[:, :40000] = rows.T
            d.attrs["MATLAB_class"] = np.bytes_("double")
            f.create_dataset("fs", data=np.array([[FS]])).attrs["MATLAB_class"] = \
                np.bytes_("double")
        else:
            d[:40000] = rows
            d.attrs["fs"] = FS
    return _mat73(path) if mat else path


@pytest.mark.parametrize("isolate", [True, False])
def test_partly_written_chunked_dataset_refused(tmp_path, isolate):
    p = _partly_written(tmp_path / "part.h5")
    with raises_naming(p, "'/acc' is only partly written: rows 0..39999 of 60000",
                       "40 of 60 chunks"):
        read_hdf5(p, isolate=isolate)
    m = _partly_written(tmp_path / "part.mat", mat=True)
    with raises_naming(m, "rows 0..39999 of 60000"):
        read_matlab(m, isolate=isolate)


def test_partly_written_with_an_explicit_fill_value_is_read(tmp_path):
    p = _partly_written(tmp_path / "filled.h5", fillvalue=-1.0)  # the writer's choice
    y = read_hdf5(p, isolate=False).y
    assert y.shape == (60000, 3)
    assert (y[:40000] != -1).all() and (y[40000:] == -1).all()


def test_unallocated_contiguous_dataset_refused(tmp_path):
    p = tmp_path / "empty.h5"
    with h5py.File(p, "w") as f:
        f.create_dataset("acc", shape=(500, 2), dtype="f8").attrs["fs"] = FS
    with raises_naming(p, "'/acc' declares 500x2 float64", "none of it was written"):
        read_hdf5(p)


def test_complete_chunked_compressed_dataset_is_read(tmp_path):
    p = tmp_path / "full.h5"
    y = np.random.default_rng(1).standard_normal((5000, 3))
    with h5py.File(p, "w") as f:
        f.create_dataset("acc", data=y, chunks=(700, 3), compression="gzip").attrs["fs"] = FS
        f.create_dataset("zeros", data=np.zeros((20000, 3)), chunks=(1000, 3),
                         compression="gzip")  # compresses ~200x: under the ratio
    np.testing.assert_array_equal(read_hdf5(p, dataset="acc").y, y)
    assert not read_hdf5(p, dataset="zeros", fs=FS).y.any()


def _tiny_declaring_huge(path, how):
    n = 250_000_000  # 2 GB of float64
    with h5py.File(path, "w") as f:
        if how == "chunked":
            d = f.create_dataset("acc", shape=(n,), dtype="f8", chunks=(1 << 16,),
                                 compression="gzip")
        elif how == "fill_value":
            d = f.create_dataset("acc", shape=(n,), dtype="f8", chunks=(1 << 16,),
                                 fillvalue=0.0)
        else:
            d = f.create_dataset("acc", shape=(n,), dtype="f8")
        d.attrs["fs"] = FS
    assert path.stat().st_size < 10_000
    return path


@pytest.mark.parametrize("how", ["chunked", "fill_value", "contiguous"])
def test_tiny_file_declaring_2gb_refused_without_allocating(tmp_path, how):
    p = _tiny_declaring_huge(tmp_path / f"huge_{how}.h5", how)
    code = PROBE + textwrap.dedent(f"""
        import modaluq.io as mio
        reset_peak()  # the child's own peak (memory_probe)
        try:
            mio.read_hdf5({str(p)!r}, isolate=False)
        except ValueError as exc:
            print("refused:", exc)
        print("maxrss_kb", memory("VmHWM") // 1024)
    """)
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         timeout=120, env={**__import__("os").environ,
                                           "PYTHONPATH": str(Path(mio.__file__).parents[2])})
    assert out.returncode == 0, out.stderr
    assert "refused:" in out.stdout and "2,000,000,000 bytes" in out.stdout, out.stdout
    assert int(out.stdout.split("maxrss_kb")[1]) < 400_000  # KB: nothing near 2 GB allocated


def test_declared_size_beyond_memory_refused(tmp_path, monkeypatch):
    p = tmp_path / "ok.h5"
    with h5py.File(p, "w") as f:
        f.create_dataset("acc", data=np.zeros((1000, 2))).attrs["fs"] = FS
    monkeypatch.setattr(hdf5, "_physical_memory", lambda: 20_000)
    with raises_naming(p, "'/acc' declares 1000x2 float64", "machine's memory"):
        read_hdf5(p, isolate=False)


# ============================================================================ item 9: parse time
def test_parse_timeout_scales_with_the_file_size():
    assert _common.parse_timeout(1_000, 60.0) == pytest.approx(5.0, abs=0.01)
    assert _common.parse_timeout(10_000_000, 60.0) == pytest.approx(15.2)
    assert _common.parse_timeout(1_000_000_000, 60.0) == pytest.approx(80.0)  # as before
    assert _common.parse_timeout(1_000, 1.5) == pytest.approx(1.5, abs=0.01)  # a lower limit
    sizes = [0, 1e3, 1e6, 5e7, 6e7, 1e9, 1e11]
    limits = [_common.parse_timeout(s, 60.0) for s in sizes]
    assert limits == sorted(limits)
    assert _common.parse_timeout(1e3) == _common.parse_timeout(1e3, mio.PARSE_TIMEOUT)


def _hanging_h5(tmp_path):
    """libhdf5 loops forever reading the string attribute of this 7.7 kB file."""
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


def test_small_looping_file_refused_within_seconds(tmp_path):
    p = _hanging_h5(tmp_path)
    assert mio.PARSE_TIMEOUT == 60.0
    t0 = time.monotonic()
    with raises_naming(p, "HDF5 parser did not finish within 5 s"):
        read_hdf5(p)
    assert time.monotonic() - t0 < 20  # not the 60 s of PARSE_TIMEOUT
