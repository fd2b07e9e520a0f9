"""Issue 26, item 9 (resources), CSV: the loader parses batches of lines into one preallocated
array, so its peak is about the array (it was ~5x the file: a 2 GB CSV took 10 GB), with the
same values, bit for bit, and the same messages (docs/loaders.md, "Memory")."""

from __future__ import annotations

import json
import os
import re
import subprocess
import sys
import textwrap
from pathlib import Path

import numpy as np
import pytest

import modaluq
import modaluq.io.csv as csv_loader
from memory_probe import PROBE
from modaluq.io import read_csv

PYTHON_DIR = str(Path(modaluq.__file__).resolve().parents[1])


def write_table(path, t, y, *, delimiter=",", line_end="\n", header=None, fmt="%.9e"):
    header = header or delimiter.join(["time [s]"] + [f"acc{k} [m/s^2]" for k in range(y.shape[1])])
    rows = [delimiter.join([f"{ti:.6f}"] + [fmt % v for v in row]) for ti, row in zip(t, y)]
    path.write_bytes((header + line_end + line_end.join(rows) + line_end).encode())


@pytest.fixture(params=[64, 1000, 1 << 20], ids=["64B", "1kB", "1MiB"])
def small_batches(request, monkeypatch):
    """Batches far smaller than the file, so that every line end falls at a batch edge once."""
    monkeypatch.setattr(csv_loader, "CHUNK_BYTES", request.param)
    return request.param


@pytest.mark.parametrize("line_end", ["\n", "\r\n", "\r"])
@pytest.mark.parametrize("delimiter", [",", ";", "\t", " "])
def test_values_identical_to_one_parse_of_the_whole_file(tmp_path, small_batches, line_end, delimiter):
    rng = np.random.default_rng(3)
    t = np.arange(300) / 50.0
    y = rng.standard_normal((300, 3)) * 10.0 ** rng.integers(-6, 6, (300, 3))
    p = tmp_path / "d.csv"
    write_table(p, t, y, delimiter=delimiter, line_end=line_end)
    rec = read_csv(p)
    whole = np.loadtxt(p.read_text().splitlines()[1:], delimiter=None if delimiter == " " else delimiter)
    assert rec.y.tobytes() == np.ascontiguousarray(whole[:, 1:]).tobytes()
    assert rec.fs == 50.0 and rec.output_units == ("m/s^2",) * 3


def test_comments_blank_lines_trailing_delimiters_and_decimal_comma(tmp_path, small_batches):
    lines = ["# logger v2", "", "time;a [g];b [g];"]
    for k in range(200):
        lines.append(f"{k / 10:.1f};{k * 0.25:.2f};{-k / 3:.6f};".replace(".", ","))
        if k % 37 == 0:
            lines += ["", "# pause"]
    p = tmp_path / "c.csv"
    p.write_text("\r\n".join(lines) + "\r\n")
    rec = read_csv(p, decimal=",")
    expected = np.array([[k * 0.25, float(f"{-k / 3:.6f}")] for k in range(200)])
    assert rec.y.tobytes() == expected.tobytes() and rec.fs == 10.0
    assert rec.output_names == ("a", "b") and rec.output_units == ("g", "g")


@pytest.mark.parametrize("cell,problem", [("nan", "NaN value ('nan')"), ("", "empty cell"),
                                          ("1.2.3", "cannot parse '1.2.3' as a number")])
def test_a_bad_cell_in_a_late_batch_is_named_by_line_and_column(tmp_path, small_batches, cell, problem):
    rows = [f"{k / 100:.2f},{k},{-k}" for k in range(2000)]
    rows[1500] = f"{15.0:.2f},{cell},7"
    p = tmp_path / "late.csv"
    p.write_text("# comment\ntime,a,b\n" + "\n".join(rows) + "\n")
    with pytest.raises(ValueError, match=re.escape(f"line {1500 + 3}, column 'a': {problem}")):
        read_csv(p)


def test_time_column_errors_still_come_after_a_bad_cell(tmp_path, small_batches):
    """The time column is found from the header before the parse; a bad cell is still reported
    first, as before."""
    p = tmp_path / "both.csv"
    p.write_text("t,a\n0,1\n0.1,x\n")
    with pytest.raises(ValueError, match="line 3, column 'a'"):
        read_csv(p, time_column="nope")
    p.write_text("t,a\n0,1\n0.1,2\n")
    with pytest.raises(ValueError, match="time_column 'nope' not found"):
        read_csv(p, time_column="nope")


# ---------------------------------------------------------------- peak memory
PEAK = """
    import json, sys
    import numpy as np
    from modaluq.io import read_csv
    small = sys.argv[1] + ".small.csv"
    with open(small, "w") as f:
        f.write("time,a\\n0,1\\n0.01,2\\n0.02,3\\n")
    read_csv(small)  # the modules the loader imports: part of the baseline
    reset_peak()
    before = memory("VmRSS")
    rec = read_csv(sys.argv[1], **json.loads(sys.argv[2]))
    peak = memory("VmHWM")
    print(json.dumps([peak - before, rec.y.nbytes, rec.y.shape[0] * 8]))
"""


@pytest.fixture(scope="module")
def csv_50mb(tmp_path_factory):
    rng = np.random.default_rng(0)
    n = 360_000
    path = tmp_path_factory.mktemp("big") / "50mb.csv"
    with open(path, "w") as f:
        f.write("time [s]," + ",".join(f"acc{k} [m/s^2]" for k in range(8)) + "\n")
        for start in range(0, n, 60_000):
            t = np.arange(start, start + 60_000) / 100.0
            np.savetxt(f, np.column_stack([t, rng.standard_normal((60_000, 8))]), delimiter=",",
                       fmt=["%.2f"] + ["%.9e"] * 8)
    assert 45e6 < path.stat().st_size < 60e6
    return path


def peak_of(path, **options):
    out = subprocess.run([sys.executable, "-c", PROBE + textwrap.dedent(PEAK), str(path), json.dumps(options)],
                         capture_output=True, text=True, timeout=300,
                         env={**os.environ, "PYTHONPATH": PYTHON_DIR + os.pathsep + os.environ.get("PYTHONPATH", "")})
    assert out.returncode == 0, out.stderr
    return json.loads(out.stdout.strip().splitlines()[-1])


@pytest.mark.skipif(not Path("/proc/self/status").exists(), reason="reads VmRSS from /proc")
def test_peak_memory_is_about_the_array(csv_50mb):
    """fs given (the time column dropped as it is parsed): the peak above the interpreter's is at
    most 1.5 times the array (it was ~10 times: the text, its lines, a parsed copy, a slice)."""
    extra, array_bytes, _ = peak_of(csv_50mb, fs=100.0)
    assert extra <= 1.5 * array_bytes, (extra / array_bytes)


@pytest.mark.skipif(not Path("/proc/self/status").exists(), reason="reads VmRSS from /proc")
def test_peak_memory_with_the_time_column_checked(csv_50mb):
    """fs from the time column: the time vector is kept and checked for a uniform grid
    (io._common.fs_from_time holds about 6 vectors of its length); documented in docs/loaders.md."""
    extra, array_bytes, time_bytes = peak_of(csv_50mb)
    assert extra <= 1.5 * array_bytes + 7 * time_bytes, (extra / array_bytes)
