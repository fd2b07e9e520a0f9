"""Tests of modaluq.io: every loader reads a file written by the format's own library."""

from __future__ import annotations

import dataclasses
import os
import pickle
import re
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from numpy.testing import assert_allclose, assert_array_equal

from modaluq.io import Recording, from_sep005, load, to_sep005

FS = 200.0
N = 400
NAMES = ["acc1", "acc2", "force", "acc3"]
UNITS = ["m/s^2", "m/s^2", "N", "m/s^2"]
SHARED = Path(__file__).resolve().parents[3].parent / "shared" / "data"
if not SHARED.is_dir():
    SHARED = Path("/work/shared/data")


@pytest.fixture(scope="module")
def samples():
    rng = np.random.default_rng(1234)
    return rng.standard_normal((N, len(NAMES)))


def raises_naming(path, exc=ValueError):
    """pytest.raises(ValueError) whose message contains the file's name."""
    return pytest.raises(exc, match=re.escape(Path(path).name))


# ============================================================================ writers
def write_csv(path, samples, *, delimiter=",", time=True, header=None, comment_lines=()):
    names = header if header is not None else [f"{n} [{u}]" for n, u in zip(NAMES, UNITS)]
    cols = list(names)
    data = samples
    if time:
        cols = ["time"] + cols
        data = np.column_stack([np.arange(samples.shape[0]) / FS, samples])
    lines = list(comment_lines) + [delimiter.join(cols)]
    lines += [delimiter.join(f"{v:.17g}" for v in row) for row in data]
    Path(path).write_text("\n".join(lines) + "\n")
    return path


def write_npz(path, samples):
    np.savez(path, y=samples[:, [0, 1, 3]], u=samples[:, [2]], fs=np.float64(FS),
             channel_names=np.array(["acc1", "acc2", "acc3"]), units=np.array(["m/s^2"] * 3),
             input_names=np.array(["force"]), input_units=np.array(["N"]))
    return path


def write_mat5(path, samples):
    sio = pytest.importorskip("scipy.io")
    sio.savemat(str(path), {"data": samples, "fs": FS, "channel_names": np.array(NAMES, dtype=object),
                            "units": np.array(UNITS, dtype=object)})
    return path


def _mat73_header(path):
    head = b"MATLAB 7.3 MAT-file, Platform: GLNXA64, Created on: Mon Jan  1 00:00:00 2024 HDF5 schema 1.00 ."
    with open(path, "r+b") as fh:
        fh.write(head.ljust(116, b" ") + b"\x00" * 8 + b"\x00\x02" + b"IM")


def write_mat73(path, samples, *, channels_first=False, names=True):
    """A MATLAB v7.3-style file: HDF5 with a 512-byte user block; arrays stored transposed."""
    h5py = pytest.importorskip("h5py")
    with h5py.File(path, "w", userblock_size=512) as f:
        matlab_array = samples.T if channels_first else samples  # what MATLAB would see
        d = f.create_dataset("acc", data=matlab_array.T)  # MATLAB column-major -> reversed
        d.attrs["MATLAB_class"] = np.bytes_("double")
        s = f.create_dataset("Fs", data=np.array([[FS]]))
        s.attrs["MATLAB_class"] = np.bytes_("double")
        if names:
            refs = f.create_group("#refs#")
            rr = []
            for i, nm in enumerate(NAMES):
                c = refs.create_dataset(f"n{i}", data=np.array([ord(ch) for ch in nm],
                                                                dtype=np.uint16)[:, None])
                c.attrs["MATLAB_class"] = np.bytes_("char")
                rr.append(c.ref)
            cell = f.create_dataset("channel_names", data=np.array(rr, dtype=h5py.ref_dtype)[:, None])
            cell.attrs["MATLAB_class"] = np.bytes_("cell")
    _mat73_header(path)
    return path


def write_hdf5(path, samples):
    h5py = pytest.importorskip("h5py")
    with h5py.File(path, "w") as f:
        d = f.create_dataset("measurement/acc", data=samples)
        d.attrs["fs"] = FS
        d.attrs["channel_names"] = NAMES
        d.attrs["units"] = UNITS
    return path


def write_uff(path, samples, *, fs=FS, binary=1, func_type=1):
    pyuff = pytest.importorskip("pyuff")
    Path(path).unlink(missing_ok=True)
    uf = pyuff.UFF(str(path))
    t = np.arange(samples.shape[0]) / fs
    for j in range(samples.shape[1]):
        ds = pyuff.prepare_58(
            func_type=func_type, rsp_node=j + 1, rsp_dir=3, ref_node=1, ref_dir=3,
            id1=NAMES[j], data=samples[:, j], x=t, abscissa_spacing=1, binary=binary,
            abscissa_spec_data_type=17, ordinate_spec_data_type=12, orddenom_spec_data_type=0,
            ordinate_axis_units_lab=UNITS[j], rsp_ent_name="str", ref_ent_name="str")
        # always "add" (to a fresh file): pyuff 2.5's "overwrite" mode truncates the header
        # of a binary record when it reopens the file for the binary payload
        uf.write_sets(ds, mode="add")
    return path


def write_tdms(path, samples, *, extra_group=True):
    nptdms = pytest.importorskip("nptdms")
    chans = [nptdms.ChannelObject("run1", nm, samples[:, j],
                                  properties={"wf_increment": 1.0 / FS, "wf_start_offset": 0.0,
                                              "unit_string": UNITS[j]})
             for j, nm in enumerate(NAMES)]
    with nptdms.TdmsWriter(str(path)) as w:
        w.write_segment([nptdms.RootObject({"title": "test"}), nptdms.GroupObject("run1")] + chans)
        if extra_group:
            w.write_segment([nptdms.ChannelObject(
                "run2", "x", samples[:100, 0] * 2, properties={"wf_increment": 0.5})])
    return path


WRITERS = {
    ".csv": write_csv, ".npz": write_npz, ".npy": lambda p, s: (np.save(p, s), p)[1],
    ".mat": write_mat5, ".h5": write_hdf5, ".uff": write_uff, ".tdms": write_tdms,
}
MAT73 = "mat73"


def _make(tmp_path, kind, samples, name="good"):
    if kind == MAT73:
        return write_mat73(tmp_path / f"{name}.mat", samples)
    return WRITERS[kind](tmp_path / f"{name}{kind}", samples)


def _load_kw(kind):
    return {".npy": {"fs": FS}}.get(kind, {})


# ============================================================================ Recording
class TestRecording:
    def test_from_arrays_split(self, samples):
        r = Recording.from_arrays(samples, FS, names=NAMES, units=UNITS, inputs=["force"],
                                  source="mem")
        assert r.y.shape == (N, 3) and r.u.shape == (N, 1)
        assert r.y.flags.c_contiguous and r.y.dtype == np.float64 and r.u.flags.c_contiguous
        assert_array_equal(r.y, samples[:, [0, 1, 3]])
        assert_array_equal(r.u, samples[:, [2]])
        assert r.output_names == ("acc1", "acc2", "acc3") and r.input_names == ("force",)
        assert r.output_units == ("m/s^2",) * 3 and r.input_units == ("N",)
        assert r.fs == FS and isinstance(r.fs, float)
        assert r.duration == pytest.approx(N / FS)
        assert r.n_samples == N and r.n_outputs == 3 and r.n_inputs == 1
        text = repr(r)
        assert f"{N} samples" in text and "200 Hz" in text and "2 s" in text and "acc1" in text

    def test_inputs_by_index_negative_and_mixed(self, samples):
        r1 = Recording.from_arrays(samples, FS, names=NAMES, inputs=[2])
        r2 = Recording.from_arrays(samples, FS, names=NAMES, inputs=[-2])
        r3 = Recording.from_arrays(samples, FS, names=NAMES, inputs=["acc1", 2])
        assert r1.input_names == r2.input_names == ("force",)
        assert r3.input_names == ("acc1", "force")
        assert_array_equal(r3.u, samples[:, [0, 2]])

    def test_defaults(self, samples):
        r = Recording.from_arrays(samples[:, 0], 10)
        assert r.y.shape == (N, 1) and r.u is None
        assert r.output_names == ("ch0",) and r.output_units == ("",)
        assert r.input_names == () and r.input_units == ()

    def test_frozen(self, samples):
        r = Recording.from_arrays(samples, FS)
        with pytest.raises(dataclasses.FrozenInstanceError):
            r.fs = 3.0

    @pytest.mark.parametrize("bad", [{"a": 1}, 3.5, [1.5], [True], "nope"])
    def test_bad_inputs_type(self, samples, bad):
        err = ValueError if bad == "nope" else TypeError
        with pytest.raises(err, match="input"):
            Recording.from_arrays(samples, FS, names=NAMES, inputs=bad)

    def test_bad_inputs_values(self, samples):
        with pytest.raises(ValueError, match="out of range"):
            Recording.from_arrays(samples, FS, inputs=[7])
        with pytest.raises(ValueError, match="more than once"):
            Recording.from_arrays(samples, FS, inputs=[1, 1])
        with pytest.raises(ValueError, match="at least one output"):
            Recording.from_arrays(samples, FS, inputs=[0, 1, 2, 3])
        with pytest.raises(ValueError, match="ambiguous"):
            Recording.from_arrays(samples[:, :2], FS, names=["a", "a"], inputs=["a"])

    @pytest.mark.parametrize("fs,err", [("100", TypeError), (None, TypeError), (True, TypeError),
                                        (0.0, ValueError), (-5, ValueError),
                                        (float("nan"), ValueError), (float("inf"), ValueError)])
    def test_bad_fs(self, samples, fs, err):
        with pytest.raises(err, match="fs"):
            Recording.from_arrays(samples, fs)

    def test_bad_samples(self):
        with pytest.raises(TypeError, match="samples"):
            Recording.from_arrays(np.array(["a", "b"]), FS)
        with pytest.raises(TypeError, match="samples"):
            Recording.from_arrays(np.ones(3) + 1j, FS)
        with pytest.raises(ValueError, match="shape"):
            Recording.from_arrays(np.ones((2, 2, 2)), FS)
        with pytest.raises(ValueError, match="names"):
            Recording.from_arrays(np.ones((5, 2)), FS, names=["a"])
        with pytest.raises(TypeError, match="names"):
            Recording.from_arrays(np.ones((5, 2)), FS, names=[1, 2])

    def test_nan_rejected(self, samples):
        s = samples.copy()
        s[17, 3] = np.nan
        with pytest.raises(ValueError, match=r"acc3.*sample 17"):
            Recording.from_arrays(s, FS, names=NAMES, source="x")

    def test_direct_construction(self, samples):
        r = Recording(y=samples[:, :2], u=None, fs=50)
        assert r.output_names == ("y0", "y1") and r.fs == 50.0
        with pytest.raises(ValueError, match="samples"):
            Recording(y=samples, u=samples[:10], fs=50)


# ============================================================================ load()
class TestLoad:
    def test_unknown_extension(self, tmp_path):
        p = tmp_path / "data.xyz"
        p.write_text("a\n1\n")
        with pytest.raises(ValueError, match=r"\.xyz.*\.csv.*\.npz.*\.mat.*\.h5.*\.uff.*\.tdms"):
            load(p)

    def test_format_override(self, tmp_path, samples):
        p = write_csv(tmp_path / "data.dat", samples)
        r = load(p, format="csv")
        assert_array_equal(r.y, samples)
        with pytest.raises(ValueError, match="unknown format"):
            load(p, format="excel")

    def test_path_type(self):
        with pytest.raises(TypeError, match="path"):
            load(123)
        with pytest.raises(TypeError, match="path"):
            load({"data": [1, 2]})

    def test_missing_file(self, tmp_path):
        with pytest.raises(FileNotFoundError, match="nope.csv"):
            load(tmp_path / "nope.csv")

    def test_directory(self, tmp_path):
        d = tmp_path / "dir.csv"
        d.mkdir()
        with raises_naming(d):
            load(d)

    def test_unexpected_option(self, tmp_path, samples):
        p = write_csv(tmp_path / "a.csv", samples)
        with pytest.raises(TypeError, match="dataset"):
            load(p, dataset="/x")

    def test_fs_type_checked(self, tmp_path, samples):
        p = write_csv(tmp_path / "a.csv", samples)
        with pytest.raises(TypeError, match="fs"):
            load(p, fs="200")

    def test_lazy_imports(self):
        code = ("import sys, modaluq.io as m; "
                "bad = [x for x in ('h5py', 'pyuff', 'nptdms', 'pandas') "
                "if sys.modules.get(x) is not None]; "
                "assert not bad, bad; m.read_csv; assert 'modaluq.io.csv' in sys.modules; "
                "assert sys.modules.get('h5py') is None")
        env = dict(os.environ, PYTHONPATH=os.pathsep.join(sys.path))
        subprocess.run([sys.executable, "-c", code], check=True, env=env)


def test_missing_optional_dependency(tmp_path, samples):
    """A missing h5py only matters for HDF5: the other loaders still work."""
    csv_path = write_csv(tmp_path / "ok.csv", samples)
    h5_path = tmp_path / "x.h5"
    h5_path.write_bytes(b"\x89HDF\r\n\x1a\n" + b"\x00" * 100)
    code = (
        "import sys; sys.modules['h5py'] = None; sys.modules['pyuff'] = None\n"
        "from modaluq.io import load\n"
        f"assert load({str(csv_path)!r}).n_samples == {N}\n"
        "try:\n"
        f"    load({str(h5_path)!r})\n"
        "except ImportError as e:\n"
        "    assert 'pip install h5py' in str(e), e\n"
        "else:\n"
        "    raise SystemExit('no ImportError')\n")
    env = dict(os.environ, PYTHONPATH=os.pathsep.join(sys.path))
    subprocess.run([sys.executable, "-c", code], check=True, env=env)


# ============================================================================ round trips
ROUND_TRIP = [".csv", ".npz", ".npy", ".mat", MAT73, ".h5", ".uff", ".tdms"]


@pytest.mark.parametrize("kind", ROUND_TRIP)
def test_round_trip(tmp_path, samples, kind):
    p = _make(tmp_path, kind, samples)
    r = load(p, **_load_kw(kind))
    assert r.fs == FS
    assert r.source == str(p)
    if kind == ".npz":  # stored u is the input by default
        assert r.input_names == ("force",)
        full = np.column_stack([r.y[:, :2], r.u, r.y[:, 2:]])
    else:
        assert r.u is None
        full = r.y
    assert full.shape == samples.shape
    assert_array_equal(full, samples)
    if kind not in (".npy",):
        names = r.output_names + r.input_names
        assert set(names) == set(NAMES)


@pytest.mark.parametrize("kind", ROUND_TRIP)
@pytest.mark.parametrize("how", ["name", "index"])
def test_input_selection(tmp_path, samples, kind, how):
    p = _make(tmp_path, kind, samples)
    kw = _load_kw(kind)
    if kind == ".npy":  # no names in a .npy: default ch0..
        sel = ["ch2"] if how == "name" else [2]
    elif kind == ".npz":  # pool: y columns (acc1, acc2, acc3) then u (force)
        sel = ["force", "acc3"] if how == "name" else [3, 2]
    else:
        sel = ["force", "acc3"] if how == "name" else [2, 3]
    r = load(p, inputs=sel, **kw)
    if kind == ".npy":
        assert_array_equal(r.u, samples[:, [2]])
        assert_array_equal(r.y, samples[:, [0, 1, 3]])
    else:
        assert r.input_names == ("force", "acc3")
        assert r.output_names == ("acc1", "acc2")
        assert_array_equal(r.u, samples[:, [2, 3]])
        assert_array_equal(r.y, samples[:, [0, 1]])
    if kind in (".csv", ".mat", ".h5", ".uff", ".tdms"):
        assert r.input_units == ("N", "m/s^2")
    with pytest.raises(ValueError, match="not found"):
        load(p, inputs=["no_such_channel"], **kw)
    with pytest.raises(TypeError, match="inputs"):
        load(p, inputs=2.5, **kw)


# ============================================================================ broken files
BROKEN = [".csv", ".npz", ".npy", ".mat", MAT73, ".h5", ".uff", ".tdms"]


def _ext(kind):
    return ".mat" if kind == MAT73 else kind


_DEPS = {".mat": ("scipy.io",), MAT73: ("scipy.io", "h5py"), ".h5": ("h5py",),
         ".uff": ("pyuff",), ".tdms": ("nptdms",)}


def _needs(*kinds):
    for kind in kinds:
        for mod in _DEPS.get(kind, ()):
            pytest.importorskip(mod)


@pytest.mark.parametrize("kind", BROKEN)
def test_corrupt_random_bytes(tmp_path, kind):
    _needs(kind)
    p = tmp_path / f"corrupt{_ext(kind)}"
    p.write_bytes(np.random.default_rng(7).integers(0, 256, 4096, dtype=np.uint8).tobytes())
    with raises_naming(p):
        load(p, fs=FS)


@pytest.mark.parametrize("kind", BROKEN)
def test_truncated(tmp_path, samples, kind):
    good = _make(tmp_path, kind, samples)
    raw = good.read_bytes()
    cut = len(raw) // 2
    if kind == ".csv":  # make sure the cut lands inside a row, after a delimiter
        cut = raw.index(b",", cut) + 1
    if kind == ".uff" and raw[cut - 7:cut] == b"    -1\n":
        cut += 10  # exactly between two records the remainder is a valid, shorter UFF file
    p = tmp_path / f"truncated{_ext(kind)}"
    p.write_bytes(raw[:cut])
    with raises_naming(p):
        load(p, fs=FS)


@pytest.mark.parametrize("kind", BROKEN)
def test_empty(tmp_path, kind):
    _needs(kind)
    p = tmp_path / f"empty{_ext(kind)}"
    p.write_bytes(b"")
    with pytest.raises(ValueError, match=re.escape(p.name) + ".*empty"):
        load(p, fs=FS)


WRONG = [(".csv", ".npz"), (".npz", ".csv"), (".npy", ".csv"), (".mat", ".npz"),
         (".h5", ".csv"), (".uff", ".csv"), (".uff", ".npz"), (".tdms", ".h5"), (".h5", ".tdms"),
         (".mat", ".uff")]


@pytest.mark.parametrize("ext,content_from", WRONG)
def test_wrong_type(tmp_path, samples, ext, content_from):
    _needs(ext, content_from)
    src = WRITERS[content_from](tmp_path / f"src{content_from}", samples)
    p = tmp_path / f"wrong{ext}"
    p.write_bytes(Path(src).read_bytes())
    with raises_naming(p):
        load(p, fs=FS)


# ============================================================================ CSV
class TestCSV:
    @pytest.mark.parametrize("delim", [",", "\t", ";", " ", "   "])
    def test_delimiters(self, tmp_path, samples, delim):
        p = write_csv(tmp_path / "d.csv", samples, delimiter=delim)
        r = load(p)
        assert_array_equal(r.y, samples)
        assert r.output_names == tuple(NAMES) and r.fs == FS

    def test_tsv_extension(self, tmp_path, samples):
        r = load(write_csv(tmp_path / "d.tsv", samples, delimiter="\t"))
        assert_array_equal(r.y, samples)

    def test_no_time_column_needs_fs(self, tmp_path, samples):
        p = write_csv(tmp_path / "nt.csv", samples, time=False)
        with pytest.raises(ValueError, match="nt.csv.*fs="):
            load(p)
        r = load(p, fs=FS)
        assert_array_equal(r.y, samples) and r.fs == FS

    def test_time_column_names_and_units(self, tmp_path, samples):
        t = np.arange(N) / 512.0
        hdr = "T_s,a1 [m/s^2],a2 (g)\n"
        rows = "\n".join(f"{a:.17g},{b:.17g},{c:.17g}" for a, b, c in
                         zip(t, samples[:, 0], samples[:, 1]))
        p = tmp_path / "u.csv"
        p.write_text(hdr + rows + "\n")
        r = load(p)
        assert r.fs == 512.0
        assert r.output_names == ("a1", "a2") and r.output_units == ("m/s^2", "g")

    def test_explicit_time_column(self, tmp_path, samples):
        t = np.arange(N) / FS
        p = tmp_path / "x.csv"
        p.write_text("clock,a\n" + "\n".join(f"{a!r},{b!r}" for a, b in
                                             zip(t.tolist(), samples[:, 0].tolist())))
        with pytest.raises(ValueError, match="fs="):
            load(p)
        assert load(p, time_column="clock").fs == FS
        assert load(p, time_column=0).output_names == ("a",)
        with pytest.raises(ValueError, match="not found"):
            load(p, time_column="zeit")
        with pytest.raises(TypeError, match="time_column"):
            load(p, time_column=1.5)
        r = load(p, time_column=False, fs=10)
        assert r.output_names == ("clock", "a")

    def test_ms_time_column(self, tmp_path):
        p = tmp_path / "ms.csv"
        p.write_text("time_ms,a\n" + "\n".join(f"{k * 2},{k % 3}" for k in range(50)))
        assert load(p).fs == 500.0

    def test_nan_names_line_and_column(self, tmp_path, samples):
        p = write_csv(tmp_path / "nan.csv", samples)
        lines = p.read_text().splitlines()
        # data row 5 (0-based) is file line 7 (header = line 1); column 'force' is field 3
        f = lines[6].split(",")
        f[3] = "NaN"
        lines[6] = ",".join(f)
        p.write_text("\n".join(lines) + "\n")
        with pytest.raises(ValueError) as ei:
            load(p)
        msg = str(ei.value)
        assert "nan.csv" in msg and "line 7" in msg and "'force'" in msg and "\n" not in msg

    def test_empty_cell_with_comment_lines(self, tmp_path, samples):
        p = write_csv(tmp_path / "gap.csv", samples, comment_lines=["# exported by logger"])
        lines = p.read_text().splitlines()
        f = lines[10].split(",")  # file line 11
        f[1] = ""
        lines[10] = ",".join(f)
        p.write_text("\n".join(lines) + "\n")
        with pytest.raises(ValueError, match=r"gap\.csv: line 11, column 'acc1': empty cell"):
            load(p)

    def test_unparsable_and_short_rows(self, tmp_path, samples):
        p = write_csv(tmp_path / "bad.csv", samples[:10], time=False)
        lines = p.read_text().splitlines()
        lines[3] = lines[3].replace(lines[3].split(",")[2], "abc", 1)
        p.write_text("\n".join(lines) + "\n")
        with pytest.raises(ValueError, match=r"bad\.csv: line 4, column 'force'.*'abc'"):
            load(p, fs=FS)
        lines = p.read_text().splitlines()
        lines[5] = ",".join(lines[5].split(",")[:2])
        lines[3] = lines[4]
        p.write_text("\n".join(lines) + "\n")
        with pytest.raises(ValueError, match=r"bad\.csv: line 6.*missing column.*'force'"):
            load(p, fs=FS)

    def test_nonuniform_time(self, tmp_path, samples):
        t = np.arange(N) / FS
        t[200:] += 0.5 / FS  # a half-sample jump
        data = np.column_stack([t, samples[:, 0]])
        p = tmp_path / "jit.csv"
        p.write_text("time,a\n" + "\n".join(f"{a!r},{b!r}" for a, b in data.tolist()))
        with pytest.raises(ValueError, match=r"jit\.csv.*not uniformly sampled"):
            load(p)
        assert load(p, fs=FS).fs == FS  # explicit fs wins
        assert load(p, time_tolerance=0.5).fs == pytest.approx(FS, rel=0.01)
        t2 = np.arange(N) / FS
        t2[10] = t2[9]
        p.write_text("time,a\n" + "\n".join(f"{a!r},1" for a in t2.tolist()))
        with pytest.raises(ValueError, match="strictly increasing"):
            load(p)

    def test_decimal_comma(self, tmp_path):
        p = tmp_path / "eu.csv"
        p.write_text("Zeit;a;b\n0,00;1,5;2\n0,01;2,5;3\n0,02;-3,25;4\n")
        r = load(p, decimal=",", time_column="Zeit")
        assert_allclose(r.y, [[1.5, 2], [2.5, 3], [-3.25, 4]])
        assert r.fs == pytest.approx(100.0)

    def test_quoted_header_crlf_bom(self, tmp_path):
        p = tmp_path / "q.csv"
        p.write_bytes(b'\xef\xbb\xbf"time","x y"\r\n0,1\r\n0.5,2\r\n1.0,3\r\n')
        r = load(p)
        assert r.output_names == ("x y",) and r.fs == 2.0
        assert_array_equal(r.y[:, 0], [1, 2, 3])

    def test_header_required(self, tmp_path):
        p = tmp_path / "nohdr.csv"
        p.write_text("1,2\n3,4\n")
        with pytest.raises(ValueError, match="nohdr.csv.*header"):
            load(p, fs=1)
        p.write_text("a,b\n")
        with pytest.raises(ValueError, match="no data rows"):
            load(p, fs=1)


# ============================================================================ NumPy
class TestNumpy:
    def test_npy_needs_fs(self, tmp_path, samples):
        p = tmp_path / "a.npy"
        np.save(p, samples)
        with pytest.raises(ValueError, match="a.npy.*fs="):
            load(p)

    def test_npy_1d(self, tmp_path, samples):
        p = tmp_path / "v.npy"
        np.save(p, samples[:, 0])
        r = load(p, fs=10, names=["v"])
        assert r.y.shape == (N, 1) and r.output_names == ("v",)

    def test_pickled_object_npy_refused(self, tmp_path):
        p = tmp_path / "obj.npy"
        np.save(p, np.array([{"a": 1}, [1, 2]], dtype=object), allow_pickle=True)
        with pytest.raises(ValueError, match=r"obj\.npy.*pickle"):
            load(p, fs=1)

    def test_pickle_file_with_npy_extension(self, tmp_path):
        p = tmp_path / "evil.npy"
        p.write_bytes(pickle.dumps(np.ones(3)))
        with raises_naming(p):
            load(p, fs=1)

    def test_pickled_object_in_npz_refused(self, tmp_path, samples):
        p = tmp_path / "obj.npz"
        np.savez(p, y=samples, fs=FS, channel_names=np.array(NAMES, dtype=object))
        with pytest.raises(ValueError, match=r"obj\.npz.*channel_names.*pickle"):
            load(p)

    def test_npz_all_outputs_and_overrides(self, tmp_path, samples):
        p = write_npz(tmp_path / "a.npz", samples)
        r = load(p, inputs=[])
        assert r.u is None and r.output_names == ("acc1", "acc2", "acc3", "force")
        assert load(p, fs=50).fs == 50.0

    def test_npz_layout_errors(self, tmp_path, samples):
        p = tmp_path / "noy.npz"
        np.savez(p, data=samples)
        with pytest.raises(ValueError, match=r"noy\.npz.*'y'"):
            load(p, fs=1)
        p = tmp_path / "badu.npz"
        np.savez(p, y=samples, u=samples[:5], fs=1.0)
        with pytest.raises(ValueError, match=r"badu\.npz.*samples"):
            load(p)
        p = tmp_path / "names.npz"
        np.savez(p, y=samples, fs=1.0, channel_names=np.array(["a"]))
        with pytest.raises(ValueError, match=r"names\.npz.*channel_names"):
            load(p)


# ============================================================================ MATLAB
class TestMatlab:
    def test_v5_channels_first_and_variable_choice(self, tmp_path, samples):
        sio = pytest.importorskip("scipy.io")
        p = tmp_path / "cf.mat"
        sio.savemat(str(p), {"A": samples.T, "B": samples[:, :2], "sampling_rate": 64.0,
                             "t": np.arange(N) / 64.0})
        with pytest.raises(ValueError, match=r"cf\.mat.*variable=.*A \(.*B \("):
            load(p)
        r = load(p, variable="A")
        assert_array_equal(r.y, samples) and r.fs == 64.0
        r = load(p, variable="A", transpose=False)
        assert r.y.shape == (len(NAMES), N)
        with pytest.raises(ValueError, match="not found"):
            load(p, variable="C")
        with pytest.raises(TypeError, match="variable"):
            load(p, variable=3)

    def test_v5_vectors_and_time_vector(self, tmp_path, samples):
        sio = pytest.importorskip("scipy.io")
        p = tmp_path / "vec.mat"
        sio.savemat(str(p), {"ax": samples[:, 0], "ay": samples[:, 1], "time": np.arange(N) / 32.0})
        r = load(p, variable=["ax", "ay"], inputs=["ay"])
        assert r.fs == 32.0 and r.output_names == ("ax",) and r.input_names == ("ay",)
        assert_array_equal(r.u[:, 0], samples[:, 1])

    def test_v5_struct_field(self, tmp_path, samples):
        sio = pytest.importorskip("scipy.io")
        p = tmp_path / "st.mat"
        sio.savemat(str(p), {"meas": {"acc": samples, "fs": FS}})
        r = load(p, variable="meas.acc", fs=FS)
        assert_array_equal(r.y, samples)

    def test_v5_no_fs(self, tmp_path, samples):
        sio = pytest.importorskip("scipy.io")
        p = tmp_path / "nofs.mat"
        sio.savemat(str(p), {"x": samples})
        with pytest.raises(ValueError, match=r"nofs\.mat.*fs="):
            load(p)
        assert load(p, fs=5).fs == 5.0

    def test_v73_transposed_storage(self, tmp_path, samples):
        p = write_mat73(tmp_path / "cf73.mat", samples, channels_first=True, names=False)
        r = load(p)  # MATLAB sees 4 x N -> samples along the long dimension
        assert_array_equal(r.y, samples)
        assert r.output_names == ("ch0", "ch1", "ch2", "ch3")
        r = load(write_mat73(tmp_path / "n73.mat", samples))
        assert r.output_names == tuple(NAMES)
        assert_array_equal(r.y, samples) and r.fs == FS


# ============================================================================ HDF5
class TestHDF5:
    def test_list_of_datasets_and_file_attr(self, tmp_path, samples):
        h5py = pytest.importorskip("h5py")
        p = tmp_path / "multi.hdf5"
        with h5py.File(p, "w") as f:
            f.attrs["sampling_rate"] = 128.0
            for j, nm in enumerate(NAMES):
                d = f.create_dataset(f"ch/{nm}", data=samples[:, j])
                d.attrs["unit"] = UNITS[j]
        with pytest.raises(ValueError, match=r"multi\.hdf5.*dataset="):
            load(p)
        r = load(p, dataset=[f"ch/{nm}" for nm in NAMES], inputs=["force"])
        assert r.fs == 128.0 and r.input_names == ("force",) and r.input_units == ("N",)
        assert_array_equal(r.u[:, 0], samples[:, 2])
        with pytest.raises(ValueError, match="not found"):
            load(p, dataset="nope")
        with pytest.raises(ValueError, match="group"):
            load(p, dataset="ch")
        with pytest.raises(TypeError, match="dataset"):
            load(p, dataset=5)

    def test_no_fs(self, tmp_path, samples):
        h5py = pytest.importorskip("h5py")
        p = tmp_path / "nofs.h5"
        with h5py.File(p, "w") as f:
            f.create_dataset("x", data=samples)
        with pytest.raises(ValueError, match=r"nofs\.h5.*fs="):
            load(p)
        r = load(p, fs=FS)
        assert_array_equal(r.y, samples)

    def test_channels_first_and_dt_attribute(self, tmp_path, samples):
        h5py = pytest.importorskip("h5py")
        p = tmp_path / "cf.h5"
        with h5py.File(p, "w") as f:
            f.create_dataset("g/x", data=samples.T.astype(np.float32))
            f["g"].attrs["dt"] = 0.25
        r = load(p)
        assert r.fs == 4.0 and r.y.dtype == np.float64
        assert_array_equal(r.y, samples.astype(np.float32))


# ============================================================================ UFF
class TestUFF:
    def test_binary_and_snapped_fs(self, tmp_path, samples):
        p = write_uff(tmp_path / "b.unv", samples, fs=300.0, binary=1)
        r = load(p)
        assert r.fs == 300.0  # increment stored as 3.33333e-03 (6 digits)
        assert_array_equal(r.y, samples)
        assert r.output_names == tuple(NAMES) and r.output_units == tuple(UNITS)

    def test_ascii_precision(self, tmp_path, samples):
        p = write_uff(tmp_path / "a.uff", samples, fs=FS, binary=0)
        r = load(p)
        assert_allclose(r.y, samples, rtol=1e-10, atol=1e-12)

    def test_frf_refused(self, tmp_path, samples):
        p = write_uff(tmp_path / "frf.uff", samples[:, :1], func_type=4)
        with pytest.raises(ValueError, match=r"frf\.uff.*function type 4"):
            load(p)

    def test_unequal_lengths(self, tmp_path, samples):
        pyuff = pytest.importorskip("pyuff")
        p = tmp_path / "uneq.uff"
        write_uff(p, samples[:, :1])
        uf = pyuff.UFF(str(p))
        uf.write_sets(pyuff.prepare_58(
            func_type=1, rsp_node=9, rsp_dir=1, ref_node=1, ref_dir=1, id1="short",
            data=samples[:50, 1], x=np.arange(50) / FS, abscissa_spacing=1,
            orddenom_spec_data_type=0, abscissa_spec_data_type=17, ordinate_spec_data_type=12,
            rsp_ent_name="s", ref_ent_name="s"), mode="add")
        with pytest.raises(ValueError, match=r"uneq\.uff.*different lengths"):
            load(p)
        assert load(p, records=[0]).n_samples == N


# ============================================================================ TDMS
class TestTDMS:
    def test_groups_and_channels(self, tmp_path, samples):
        p = write_tdms(tmp_path / "g.tdms", samples)
        r = load(p, group="run2")
        assert r.fs == 2.0 and r.output_names == ("x",)
        r = load(p, channels=["acc3", "acc1"], inputs=[1])
        assert r.output_names == ("acc3",) and r.input_names == ("acc1",)
        with pytest.raises(ValueError, match=r"g\.tdms.*group 'nope' not found"):
            load(p, group="nope")
        with pytest.raises(ValueError, match="not in group"):
            load(p, channels=["zz"])
        with pytest.raises(TypeError, match="group"):
            load(p, group=1)

    def test_time_channel(self, tmp_path, samples):
        nptdms = pytest.importorskip("nptdms")
        p = tmp_path / "tc.tdms"
        with nptdms.TdmsWriter(str(p)) as w:
            w.write_segment([nptdms.ChannelObject("g", "Time", np.arange(N) / 50.0),
                             nptdms.ChannelObject("g", "a", samples[:, 0])])
        r = load(p)
        assert r.fs == 50.0 and r.output_names == ("a",)

    def test_no_fs(self, tmp_path, samples):
        nptdms = pytest.importorskip("nptdms")
        p = tmp_path / "nofs.tdms"
        with nptdms.TdmsWriter(str(p)) as w:
            w.write_segment([nptdms.ChannelObject("g", "a", samples[:, 0])])
        with pytest.raises(ValueError, match=r"nofs\.tdms.*fs="):
            load(p)
        assert load(p, fs=10).fs == 10.0


# ============================================================================ SEP005
class TestSEP005:
    def test_list_of_dicts(self, samples):
        chans = [{"data": samples[:, j], "name": nm, "unit_str": UNITS[j], "fs": FS,
                  "quantity": "a"} for j, nm in enumerate(NAMES)]
        r = from_sep005(chans, inputs=["force"])
        assert r.fs == FS and r.input_names == ("force",) and r.input_units == ("N",)
        assert_array_equal(r.u[:, 0], samples[:, 2])
        assert r.source == "SEP005"

    def test_time_and_tolerant_keys(self, samples):
        t = (np.arange(N) / FS).tolist()
        chans = [{"Data": samples[:, 0].tolist(), "Name": "a", "unit": "m", "time": t},
                 {"data": samples[:, 1], "name": "b", "unit_str": "m", "time": t}]
        r = from_sep005(chans)
        assert r.fs == FS and r.output_units == ("m", "m")
        assert_array_equal(r.y, samples[:, :2])

    def test_single_dict_and_round_trip(self, samples):
        r = from_sep005({"data": samples[:, 0], "name": "a", "unit_str": "g", "fs": 10})
        assert r.y.shape == (N, 1)
        rec = Recording.from_arrays(samples, FS, names=NAMES, units=UNITS, inputs=[2])
        back = from_sep005(to_sep005(rec), inputs=["force"])
        assert_array_equal(back.y, rec.y) and assert_array_equal(back.u, rec.u)
        assert back.output_names == rec.output_names and back.fs == rec.fs

    def test_errors(self, samples):
        with pytest.raises(ValueError, match="different lengths"):
            from_sep005([{"data": samples[:, 0], "name": "a", "fs": 1},
                         {"data": samples[:10, 1], "name": "b", "fs": 1}])
        with pytest.raises(ValueError, match="different fs"):
            from_sep005([{"data": samples[:, 0], "name": "a", "fs": 1},
                         {"data": samples[:, 1], "name": "b", "fs": 2}])
        with pytest.raises(ValueError, match="fs="):
            from_sep005([{"data": samples[:, 0], "name": "a"}])
        with pytest.raises(ValueError, match="'a'.*sample 1"):
            from_sep005([{"data": [1.0, None, 3.0], "name": "a", "fs": 1}])
        with pytest.raises(TypeError, match="channels"):
            from_sep005("abc")
        with pytest.raises(TypeError, match=r"channels\[1\]"):
            from_sep005([{"data": [1.0], "fs": 1}, 5])

    def test_sdypy_validator_accepts_export(self, samples):
        sep = pytest.importorskip("sdypy_sep005.sep005")
        rec = Recording.from_arrays(samples[:20], FS, names=NAMES, units=UNITS)
        sep.assert_sep005(to_sep005(rec))


# ============================================================================ shared data
SHARED_FILES = sorted(SHARED.glob("*.npz")) if SHARED.is_dir() else []


@pytest.mark.skipif(not SHARED_FILES, reason="shared/data not available")
@pytest.mark.parametrize("path", SHARED_FILES, ids=lambda p: p.stem)
def test_shared_datasets(path):
    r = load(path)
    with np.load(path, allow_pickle=False) as z:
        assert_array_equal(r.y, z["y"])
        assert r.fs == float(z["fs"])
        assert r.output_names == tuple(z["channel_names"].tolist())
        assert r.output_units == tuple(z["units"].tolist())
        if "u" in z.files:
            assert_array_equal(r.u, z["u"])
            assert r.input_names == tuple(z["input_names"].tolist())
            assert r.input_units == tuple(z["input_units"].tolist())
        else:
            assert r.u is None
    assert r.y.flags.c_contiguous and r.y.dtype == np.float64
    assert np.isfinite(r.y).all()
