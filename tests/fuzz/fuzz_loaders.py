#!/usr/bin/env python3
"""Mutation fuzzing of ``modaluq.io.load``: the loader contract under corrupt input.

Seed files are written by each format's own library (csv module, numpy, SciPy, h5py, pyuff,
npTDMS), then mutated (bit flips, byte sets, "interesting" integers, truncations, insertions,
deletions, chunk duplications; 1-4 per input) and loaded. Each call must either succeed or raise
ValueError / OSError whose message names the file. Anything else is a failure, and so is a call
over ``--hang`` seconds; failures print a reproducer and save the input. A crash of this
process must not happen: the parsers that can crash run isolated (``isolate=True``).

    python3 tests/fuzz/fuzz_loaders.py --seconds 60 [--format mat5] [--runs N] [--seed K]

Deterministic for a given --seed: input number N is the same whatever the time budget, and
``--replay N --format F`` writes it again. Exit status 1 on any failure.
"""

from __future__ import annotations

import argparse
import faulthandler
import importlib
import logging
import os
import random
import shutil
import signal
import sys
import tempfile
import time
from collections import Counter
from pathlib import Path

import numpy as np

FS = 100.0
#: format -> (file extension, load keywords)
FORMATS = {
    "csv": (".csv", {}), "npy": (".npy", {"fs": FS}), "npz": (".npz", {}), "mat5": (".mat", {}),
    "mat73": (".mat", {}), "hdf5": (".h5", {}), "uff": (".uff", {}), "tdms": (".tdms", {}),
}
# the reader of each is modaluq.io's for its extension (modaluq.io.FILE_FORMATS; a test checks
# that every format there has a seed here)
_INTERESTING = (0, 1, 0x7F, 0x80, 0xFF, 0x7FFF, 0xFFFF, 0x7FFFFFFF, 0xFFFFFFFF, 2**63 - 1,
                2**64 - 1, 4096, 65536)


# ---------------------------------------------------------------------------- seeds
def _signal(n=64, nch=2, seed=0):
    return np.random.default_rng(seed).standard_normal((n, nch))


def _seed_csv(d):
    y = _signal()
    out = []
    for k, (hdr, delim) in enumerate((("time [s],a1 [m/s^2],a2 [m/s^2]", ","),
                                      ("t (ms);a1;a2", ";"), ("Time_msec\ta1\ta2", "\t"))):
        scale = 1.0 if k == 0 else 1e3
        rows = [delim.join(f"{v:.6g}" for v in (i / FS * scale, *y[i])) for i in range(len(y))]
        p = d / f"csv{k}.csv"
        p.write_text("# comment\n" + hdr + "\n" + "\n".join(rows) + "\n")
        out.append(p)
    return out


def _seed_npy(d):
    p = d / "a.npy"
    np.save(p, _signal())
    return [p]


def _seed_npz(d):
    y = _signal()
    p1, p2 = d / "a.npz", d / "b.npz"
    np.savez(p1, y=y, u=y[:, :1], fs=np.float64(FS), channel_names=np.array(["a", "b"]),
             units=np.array(["m/s^2"] * 2))
    np.savez_compressed(p2, y=y, fs=np.float64(FS))
    return [p1, p2]


def _fixed_mat_header(p):  # savemat stamps the creation time: make the seed reproducible
    raw = bytearray(p.read_bytes())
    raw[:116] = b"MATLAB 5.0 MAT-file, modaluq fuzz seed".ljust(116)
    p.write_bytes(bytes(raw))


def _seed_mat5(d):
    import scipy.io as sio

    y = _signal()
    out = []
    for k, comp in enumerate((False, True)):
        p = d / f"m{k}.mat"
        sio.savemat(str(p), {"data": y, "fs": FS, "channel_names": np.array(["a", "b"],
                                                                          dtype=object),
                             "meta": {"units": "m/s^2", "dt": 1 / FS}}, do_compression=comp)
        _fixed_mat_header(p)
        out.append(p)
    return out


def _seed_mat73(d):
    import h5py

    p = d / "m73.mat"
    with h5py.File(p, "w", userblock_size=512) as f:
        ds = f.create_dataset("acc", data=_signal().T)
        ds.attrs["MATLAB_class"] = np.bytes_("double")
        s = f.create_dataset("Fs", data=np.array([[FS]]))
        s.attrs["MATLAB_class"] = np.bytes_("double")
        refs = f.create_group("#refs#")
        rr = []
        for i, nm in enumerate(("a1", "a2")):
            c = refs.create_dataset(f"n{i}", data=np.array([ord(ch) for ch in nm],
                                                           dtype=np.uint16)[:, None])
            c.attrs["MATLAB_class"] = np.bytes_("char")
            rr.append(c.ref)
        cell = f.create_dataset("channel_names", data=np.array(rr, dtype=h5py.ref_dtype)[:, None])
        cell.attrs["MATLAB_class"] = np.bytes_("cell")
    with open(p, "r+b") as fh:
        fh.write(b"MATLAB 7.3 MAT-file, modaluq fuzz seed".ljust(116) + b"\0" * 8 + b"\0\x02IM")
    return [p]


def _seed_hdf5(d):
    import h5py

    p1, p2 = d / "a.h5", d / "b.h5"
    with h5py.File(p1, "w") as f:
        ds = f.create_dataset("meas/acc", data=_signal())
        ds.attrs["fs"] = FS
        ds.attrs["channel_names"] = ["a1", "a2"]  # variable-length strings: the global heap
        ds.attrs["units"] = ["m/s^2", "m/s^2"]
    with h5py.File(p2, "w") as f:
        f.create_dataset("acc", data=_signal(), chunks=(16, 2), compression="gzip")
        f.create_dataset("time", data=np.arange(64) / FS)
    return [p1, p2]


def _seed_uff(d):
    import pyuff

    out = []
    for binary in (0, 1):
        p = d / f"u{binary}.uff"
        uf = pyuff.UFF(str(p))
        y = _signal(32)
        for j in range(2):
            uf.write_sets(pyuff.prepare_58(
                func_type=1, rsp_node=j + 1, rsp_dir=3, ref_node=1, ref_dir=3, id1=f"a{j}",
                data=y[:, j], x=np.arange(32) / FS, abscissa_spacing=1, binary=binary,
                abscissa_spec_data_type=17, ordinate_spec_data_type=12,
                orddenom_spec_data_type=0, ordinate_axis_units_lab="m/s^2",
                rsp_ent_name="s", ref_ent_name="s"), mode="add")
        out.append(p)
    return out


def _seed_tdms(d):
    import nptdms

    p = d / "a.tdms"
    y = _signal()
    with nptdms.TdmsWriter(str(p)) as w:
        for k in range(2):  # two segments: the second one's lead-in can be cut
            w.write_segment([nptdms.ChannelObject(
                "g", f"a{j}", y[32 * k:32 * (k + 1), j],
                properties={"wf_increment": 1 / FS, "unit_string": "m/s^2"}) for j in range(2)])
    return [p]


SEEDS = {"csv": _seed_csv, "npy": _seed_npy, "npz": _seed_npz, "mat5": _seed_mat5,
         "mat73": _seed_mat73, "hdf5": _seed_hdf5, "uff": _seed_uff, "tdms": _seed_tdms}


# ---------------------------------------------------------------------------- mutator
def mutate(data: bytes, rng: random.Random) -> bytes:
    b = bytearray(data)
    for _ in range(rng.choice((1, 1, 1, 2, 2, 3, 4))):
        n = len(b)
        op = rng.randrange(8) if n else 3
        if op == 0:  # bit flip
            i = rng.randrange(n)
            b[i] ^= 1 << rng.randrange(8)
        elif op == 1:  # byte set
            b[rng.randrange(n)] = rng.choice((0, 0xFF, 0x7F, 0x80, rng.randrange(256)))
        elif op == 2:  # interesting little/big-endian integer of 1, 2, 4 or 8 bytes
            w = rng.choice((1, 2, 4, 8))
            v = rng.choice(_INTERESTING) & ((1 << 8 * w) - 1)
            i = rng.randrange(max(n - w, 0) + 1)
            b[i:i + w] = v.to_bytes(w, rng.choice(("little", "big")))
        elif op == 3:  # insertion
            i = rng.randrange(n + 1)
            b[i:i] = bytes(rng.choice((rng.randrange(256), 0, 0x0D, 0x22, 0x2C)) for _ in
                           range(rng.choice((1, 1, 4, 16))))
        elif op == 4:  # truncation
            del b[rng.randrange(n):]
        elif op == 5:  # deletion of a chunk
            i = rng.randrange(n)
            del b[i:i + rng.randrange(1, 64)]
        elif op == 6:  # duplication of a chunk elsewhere
            i = rng.randrange(n)
            chunk = b[i:i + rng.randrange(1, 256)]
            j = rng.randrange(len(b) + 1)
            b[j:j] = chunk
        else:  # overwrite with a chunk from elsewhere
            i, j = rng.randrange(n), rng.randrange(n)
            ln = rng.randrange(1, 64)
            b[j:j + ln] = b[i:i + ln]
    return bytes(b)


# ---------------------------------------------------------------------------- harness
class _Hang(Exception):
    pass


def _alarm(signum, frame):
    raise _Hang


def classify(path: Path, load, kwargs) -> tuple[str, str]:
    """('ok' | 'rejected' | 'failure', detail) for one load of ``path``."""
    try:
        load(path, **kwargs)
        return "ok", ""
    except _Hang:
        raise
    except (ValueError, OSError) as exc:
        if path.name in str(exc):
            return "rejected", str(exc)
        return "failure", f"{type(exc).__name__} not naming the file: {exc}"
    except Exception as exc:  # noqa: BLE001 - this is what the fuzzer looks for
        return "failure", f"{type(exc).__name__}: {exc}"


def fuzz(formats=None, *, seconds=None, runs=None, seed=0, hang=10.0, save_dir=None,
         log=print) -> dict:
    """Fuzz each format for ``seconds`` (each) and/or ``runs`` inputs; return
    {format: Counter(ok=, rejected=, failure=, hang=, runs=)} and list failures in
    ``result[fmt]['failures']`` as (saved path or None, detail)."""
    import modaluq.io as mio

    try:  # npTDMS prints its warnings (which the loader turns into errors) to stderr
        import nptdms.log

        nptdms.log.log_manager.console_handler.setLevel(logging.CRITICAL)
    except (ImportError, AttributeError):
        pass
    formats = list(formats or FORMATS)
    if seconds is None and runs is None:
        runs = 100
    # a hang in the isolated child is stopped by the loader well before our own limit
    old_timeout, mio.PARSE_TIMEOUT = mio.PARSE_TIMEOUT, max(hang / 2, 0.5)
    old_handler = signal.signal(signal.SIGALRM, _alarm) if hasattr(signal, "SIGALRM") else None
    results = {}
    try:
        # inputs are rewritten thousands of times a second: keep them in memory when possible
        shm = "/dev/shm" if os.path.isdir("/dev/shm") and os.access("/dev/shm", os.W_OK) else None
        with tempfile.TemporaryDirectory(prefix="modaluq-fuzz-", dir=shm) as tmp:
            tmp = Path(tmp)
            for fmt in formats:
                ext, kwargs = FORMATS[fmt]
                sdir = tmp / f"seeds-{fmt}"
                sdir.mkdir()
                try:
                    seeds = [p.read_bytes() for p in SEEDS[fmt](sdir)]
                except ImportError as exc:
                    log(f"{fmt}: skipped ({exc})")
                    continue
                rng = random.Random(f"{seed}:{fmt}")
                target = tmp / f"input-{fmt}{ext}"
                counts, failures, slowest, slowest_run = Counter(), [], 0.0, (0, 0.0)
                t_end = None if seconds is None else time.monotonic() + seconds
                for s in seeds:  # the unmutated seeds must load
                    target.write_bytes(s)
                    mio.load(target, **kwargs)
                while (runs is None or counts["runs"] < runs) and \
                        (t_end is None or time.monotonic() < t_end):
                    data = mutate(rng.choice(seeds), rng)
                    if not data:
                        data = b"\0"
                    target.write_bytes(data)
                    # last resort for a hang inside C code that SIGALRM cannot interrupt
                    faulthandler.dump_traceback_later(hang * 3, exit=True)
                    if old_handler is not None:
                        signal.setitimer(signal.ITIMER_REAL, hang * 1.5)
                    t0, c0 = time.perf_counter(), time.process_time()
                    try:
                        outcome, detail = classify(target, mio.load, kwargs)
                    except _Hang:
                        outcome, detail = "failure", f"hang (> {hang * 1.5:g} s, interrupted)"
                    finally:
                        if old_handler is not None:
                            signal.setitimer(signal.ITIMER_REAL, 0)
                        faulthandler.cancel_dump_traceback_later()
                    dt, cpu = time.perf_counter() - t0, time.process_time() - c0
                    if dt > slowest:
                        slowest, slowest_run = dt, (counts["runs"] + 1, cpu)
                    if dt > hang:
                        outcome, detail = "failure", (f"took {dt:.1f} s ({cpu:.1f} s CPU here; "
                                                      f"limit {hang:g} s) {detail}")
                        counts["hang"] += 1
                    counts["runs"] += 1
                    counts[outcome] += 1
                    if outcome == "rejected":  # how often the isolation had to step in
                        counts["crash"] += "parser crashed" in detail
                        counts["stopped"] += "did not finish within" in detail
                    contained = outcome == "rejected" and ("parser crashed" in detail or
                                                           "did not finish within" in detail)
                    if (dt > hang / 4 or contained) and save_dir is not None and \
                            outcome != "failure":
                        # kept to find what to validate before the parser, or a stall
                        Path(save_dir).mkdir(parents=True, exist_ok=True)
                        tag = "contained" if contained else "slow"
                        shutil.copyfile(target, Path(save_dir) /
                                        f"{tag}-{fmt}-{seed}-{counts['runs']}-{dt:.1f}s{ext}")
                    if outcome == "failure":
                        saved = None
                        if save_dir is not None:
                            Path(save_dir).mkdir(parents=True, exist_ok=True)
                            saved = Path(save_dir) / f"{fmt}-{seed}-{counts['runs']}{ext}"
                            shutil.copyfile(target, saved)
                        failures.append((saved, detail))
                        log(f"FAILURE {fmt} run {counts['runs']}: {detail}\n  reproduce: "
                            f"python3 -c \"import modaluq.io as m; m.load({str(saved)!r}"
                            f"{''.join(f', {k}={v!r}' for k, v in kwargs.items())})\"")
                counts_fail = counts["failure"]
                log(f"{fmt:6s}: {counts['runs']} inputs, {counts['ok']} loaded, "
                    f"{counts['rejected']} rejected with ValueError/OSError naming the file, "
                    f"{counts_fail} failures ({counts['hang']} hangs > {hang:g} s); isolated "
                    f"parser crashes contained {counts['crash']}, hangs stopped "
                    f"{counts['stopped']}; "
                    f"slowest {slowest:.2f} s (input {slowest_run[0]}, "
                    f"{slowest_run[1]:.2f} s CPU in this process)")
                results[fmt] = dict(counts, failures=failures)
    finally:
        mio.PARSE_TIMEOUT = old_timeout
        if old_handler is not None:
            signal.signal(signal.SIGALRM, old_handler)
    return results


def replay(fmt: str, run: int, seed: int, out_dir) -> Path:
    """Write input number ``run`` (1-based, as reported) of ``fmt`` for ``seed`` to ``out_dir``:
    the inputs depend only on the seed and their number, not on the time budget."""
    ext = FORMATS[fmt][0]
    with tempfile.TemporaryDirectory() as tmp:
        seeds = [p.read_bytes() for p in SEEDS[fmt](Path(tmp))]
    rng = random.Random(f"{seed}:{fmt}")
    for _ in range(run):
        data = mutate(rng.choice(seeds), rng) or b"\0"
    out = Path(out_dir) / f"{fmt}-{seed}-{run}{ext}"
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_bytes(data)
    return out


def fuzz_atheris(fmt: str, *, seconds, runs, seed, hang, save_dir) -> None:
    """Coverage-guided variant (``--engine atheris``, one format per process): libFuzzer mutates
    the same seed files, guided by coverage of the Python code (our loaders, npTDMS, pyuff, the
    Python layers of SciPy and h5py; their C code is not instrumented). Exits the process:
    status 0 when libFuzzer's "Done N runs" found no failure."""
    import atheris

    # instrument only the loader and the pure-Python format libraries (all of numpy and SciPy
    # takes minutes): they must be imported here for the first time
    with atheris.instrument_imports(include=["modaluq.io", "nptdms", "pyuff"]):
        import modaluq.io as mio

        importlib.import_module(f"modaluq.io.{mio.FORMATS[mio.SUPPORTED_EXTENSIONS[FORMATS[fmt][0]]][0]}")
        for lib in ("nptdms", "pyuff"):
            try:
                importlib.import_module(lib)
            except ImportError:
                pass
    ext, kwargs = FORMATS[fmt]
    tmp = Path(tempfile.mkdtemp(prefix="modaluq-atheris-"))
    corpus = tmp / "corpus"
    corpus.mkdir()
    SEEDS[fmt](corpus)
    target = tmp / f"input{ext}"
    mio.PARSE_TIMEOUT = max(hang / 2, 0.5)
    counts = Counter()

    def one(data: bytes) -> None:
        target.write_bytes(data or b"\0")
        outcome, detail = classify(target, mio.load, kwargs)
        counts["runs"] += 1
        counts[outcome] += 1
        if counts["runs"] % 10000 == 0:  # libFuzzer ends with _exit: no summary at exit
            print(f"{fmt:6s}: {counts['runs']} inputs (atheris), {counts['ok']} loaded, "
                  f"{counts['rejected']} rejected, 0 failures", flush=True)
        if outcome == "failure":  # libFuzzer saves the input under -artifact_prefix
            raise RuntimeError(detail)

    Path(save_dir).mkdir(parents=True, exist_ok=True)
    args = [sys.argv[0], f"-seed={seed}", f"-timeout={int(hang)}", "-rss_limit_mb=4096",
            f"-artifact_prefix={Path(save_dir).resolve()}/{fmt}-", str(corpus)]
    args += [f"-max_total_time={int(seconds)}"] if seconds else []
    args += [f"-runs={runs}"] if runs else []
    atheris.Setup(args, one)
    atheris.Fuzz()


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--seconds", type=float, default=None, help="time budget per format")
    ap.add_argument("--runs", type=int, default=None, help="inputs per format")
    ap.add_argument("--format", action="append", choices=sorted(FORMATS),
                    help="format(s) to fuzz (repeatable); default all")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--hang", type=float, default=10.0, help="seconds counted as a hang")
    ap.add_argument("--save-dir", default="fuzz-failures", help="where failing inputs go")
    ap.add_argument("--engine", choices=("random", "atheris"), default="random",
                    help="the built-in deterministic mutator, or coverage-guided atheris "
                         "(pip install atheris; one --format per run)")
    ap.add_argument("--replay", type=int, metavar="N",
                    help="only write input number N of each --format (for --seed) to --save-dir")
    a = ap.parse_args(argv)
    if a.replay is not None:
        for fmt in a.format or FORMATS:
            print(replay(fmt, a.replay, a.seed, a.save_dir))
        return 0
    if a.seconds is None and a.runs is None:
        a.seconds = 10.0
    if a.engine == "atheris":
        if not a.format or len(a.format) != 1:
            ap.error("--engine atheris fuzzes one --format per process")
        fuzz_atheris(a.format[0], seconds=a.seconds, runs=a.runs, seed=a.seed, hang=a.hang,
                     save_dir=a.save_dir)
    res = fuzz(a.format, seconds=a.seconds, runs=a.runs, seed=a.seed, hang=a.hang,
               save_dir=a.save_dir, log=lambda m: print(m, flush=True))
    total = sum(r["failure"] for r in res.values() if "failure" in r)
    print(f"total: {sum(r['runs'] for r in res.values())} inputs, {total} failures", flush=True)
    return 1 if total else 0


if __name__ == "__main__":
    sys.exit(main())
