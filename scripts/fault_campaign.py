"""Fault campaign before a release (issue 26): kill -9, two runs at once, a full disk.

Runs the real command ``python -m modaluq.cli monitor ... --threads 1 --no-progress
--settle-seconds 0`` on a small simulated campaign (12 records of 6000 samples, ``.npz``) and,
for a NetCDF store (``tracks.nc``) and a Zarr store (``tracks.zarr``):

1. **kill -9 at random moments.** An uninterrupted run is timed first (and its store, pole and
   failures tables kept as the reference). Then ``--kills N`` times: the run is started and its
   whole process group gets SIGKILL at a random moment, a third of them drawn over the whole run, a
   third over its last 20 % and a third from the moment the uninterrupted run's first output
   temporary appeared to its end (the write). Trials alternate between an
   empty output folder and one holding the store of an earlier run on the first 8 records (so a
   kill during the write replaces an existing store). After each kill: the store is absent (only
   when there was none before) or readable (``xarray.open_dataset`` / ``xarray.open_zarr``, loaded)
   and equal to the previous store or to the reference; the pole and failures tables are the old
   bytes or the new. Then the same command is run to completion and the store must be identical to
   the reference (``xarray.testing.assert_identical``), the tables byte-equal, and no temporary
   left beside the store (``*.tmp-<pid>``, ``*.old-<pid>``, ``.*.tmp``; the lock file
   ``<stem>.lock`` and ``<stem>.parts/`` are expected).
2. **Two runs at once** (``--rounds``): a second run on the store while the first holds its lock
   (same command, or ``--no-resume``) must exit 2 naming the holder's pid; the first completes
   with the reference store.
3. **A full disk** (root only: a small tmpfs is mounted): the store of 8 records and the parts of
   all 12 on a tmpfs filled but for 16 kB; the run must fail (exit 2) naming the output that
   could not be written, leave the previous store and pole table as they were and write the
   failures table; after space is freed the resume gives the reference.

    python scripts/fault_campaign.py                  # 30 kills per format, about 10 minutes
    python scripts/fault_campaign.py --kills 5 --rounds 1 --seed 7

Prints one line per kill and a summary table; exits 1 if anything was not as it must be. The
package is the repository's (``python/``) when its compiled core is there, else the installed one.
"""

from __future__ import annotations

import argparse
import os
import random
import re
import shutil
import signal
import subprocess
import sys
import tempfile
import time
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
N_RECORDS, N_SAMPLES, N_PREVIOUS = 12, 6000, 8
TEMPORARY = re.compile(r"(\.tmp-\d+|\.old-\d+)$|^\..*\.tmp$")


def _env() -> dict:
    env = dict(os.environ)
    if list((REPO / "python" / "modaluq").glob("_core*.so")):
        env["PYTHONPATH"] = str(REPO / "python") + (os.pathsep + env["PYTHONPATH"] if env.get("PYTHONPATH") else "")
    return env


ENV = _env()
if "PYTHONPATH" in ENV:
    sys.path[:0] = ENV["PYTHONPATH"].split(os.pathsep)

import xarray as xr  # noqa: E402


def say(*args) -> None:
    print(*args, flush=True)  # noqa: T201


# ---- the campaign's files ---------------------------------------------------------------------------------------


def simulate(work: Path, seed: int) -> tuple:
    import modaluq

    sim = modaluq.simulate_monitoring(N_RECORDS, n_samples=N_SAMPLES, seed=seed)
    paths = sim.write(work / "records", format="npz", covariates=work / "covariates.csv")
    return [str(p) for p in paths], str(work / "covariates.csv")


def command(records: list, covariates: str, store: Path, *extra: str) -> list:
    return [sys.executable, "-m", "modaluq.cli", "monitor", *records, "--covariates", covariates,
            "--out", str(store), "--threads", "1", "--no-progress", "--settle-seconds", "0",
            "--reference-records", "6", *extra]


def start(cmd: list, log: Path) -> subprocess.Popen:
    with open(log, "wb") as fh:  # the child keeps its own descriptor
        return subprocess.Popen(cmd, stdout=fh, stderr=subprocess.STDOUT, env=ENV, start_new_session=True)


def run(cmd: list, log: Path) -> tuple:
    """Run to completion: (exit status, seconds, output)."""
    t0 = time.monotonic()
    proc = start(cmd, log)
    code = proc.wait()
    return code, time.monotonic() - t0, log.read_text(errors="replace")


def tables(store: Path) -> dict:
    stem = store.with_suffix("")
    return {"poles": Path(f"{stem}.poles.csv"), "failures": Path(f"{stem}.failures.csv")}


def read_store(store: Path):
    """The store loaded, or raises if unreadable."""
    if store.suffix == ".nc":
        with xr.open_dataset(store) as ds:
            return ds.load()
    with xr.open_zarr(store) as ds:
        return ds.load()


def identical(a, b) -> bool:
    try:
        xr.testing.assert_identical(a, b)
        return True
    except AssertionError:
        return False


def leftovers(folder: Path, store: Path) -> list:
    """Temporaries beside the store or in its parts folder (not inside the store itself)."""
    found = []
    for root, dirs, files in os.walk(folder):
        root = Path(root)
        if root == store:
            dirs[:] = []
            continue
        for name in dirs + files:
            if TEMPORARY.search(name):
                found.append(str((root / name).relative_to(folder)))
        dirs[:] = [d for d in dirs if root / d != store]
    return sorted(found)


def n_parts(store: Path) -> int:
    parts = store.with_name(store.stem + ".parts")
    return len([p for p in parts.glob("*.json") if p.name != "settings.json"]) if parts.is_dir() else 0


def snapshot(out: Path, store: Path) -> dict:
    """What a run left: the store, the tables' bytes (None where absent)."""
    return {"store": read_store(store) if store.exists() else None,
            **{k: p.read_bytes() if p.exists() else None for k, p in tables(store).items()}}


def reset(folder: Path, source: Path | None) -> None:
    shutil.rmtree(folder, ignore_errors=True)
    if source is None:
        folder.mkdir(parents=True)
    else:
        shutil.copytree(source, folder, symlinks=True)


# ---- 1. kill -9 -------------------------------------------------------------------------------------------------


def timed_run(cmd: list, out: Path, store: Path, log: Path) -> dict:
    """Run to completion, noting when every record is done and when the first output temporary appears."""
    t0 = time.monotonic()
    proc = start(cmd, log)
    t_write = t_parts = None
    while proc.poll() is None:
        now = time.monotonic() - t0
        if t_parts is None and n_parts(store) == N_RECORDS:
            t_parts = now
        if t_write is None and any(TEMPORARY.search(p.name) for p in out.iterdir()):
            t_write = now
        time.sleep(0.005)
    seconds = time.monotonic() - t0
    if proc.returncode != 0:
        raise SystemExit(f"an uninterrupted run failed ({proc.returncode}): {log.read_text()}")
    return {"seconds": seconds, "all_parts": t_parts or seconds, "write": t_write or seconds}


def reference(kind: str, base: Path, records: list, cov: str) -> dict:
    """The uninterrupted runs: from nothing (timed, with the moment the write starts) and the store of
    the first 8 records (the 'previous store' of half the trials) with the 12-record run after it."""
    ref = {}
    out = base / "reference"
    reset(out, None)
    store = out / f"tracks.{kind}"
    ref["fresh"] = timed_run(command(records, cov, store), out, store, base / "reference.log")
    ref["final"] = snapshot(out, store)
    # the previous store: a run on the first 8 records, kept as the starting folder of half the trials
    prev = base / "previous"
    reset(prev, None)
    pstore = prev / f"tracks.{kind}"
    code, _, text = run(command(records[:N_PREVIOUS], cov, pstore), base / "previous.log")
    if code != 0:
        raise SystemExit(f"the 8-record run failed ({code}): {text}")
    ref["previous"] = snapshot(prev, pstore)
    upd = base / "update"
    reset(upd, prev)
    ustore = upd / f"tracks.{kind}"
    ref["update"] = timed_run(command(records, cov, ustore), upd, ustore, base / "update.log")
    got = snapshot(upd, ustore)
    if not identical(got["store"], ref["final"]["store"]) or got["poles"] != ref["final"]["poles"]:
        raise SystemExit("the run that adds 4 records to a store of 8 differs from the run of 12 from nothing")
    return ref


def kills(kind: str, base: Path, records: list, cov: str, ref: dict, n: int, rng: random.Random) -> list:
    rows = []
    trial = base / "trial"
    logs = base / "logs"
    logs.mkdir(exist_ok=True)
    i = 0
    while len(rows) < n and i < 3 * n:
        i += 1
        mode = ("fresh", "update")[len(rows) % 2]
        seconds, t_write = ref[mode]["seconds"], ref[mode]["write"]
        where = rng.choice(("anywhere", "last 20 %", "write"))
        low = {"anywhere": 0.0, "last 20 %": 0.8 * seconds, "write": max(0.0, t_write - 0.05)}[where]
        t_kill = rng.uniform(low, seconds)
        late = t_kill >= 0.8 * seconds
        reset(trial, None if mode == "fresh" else base / "previous")
        store = trial / f"tracks.{kind}"
        before = ref["previous"] if mode == "update" else {"store": None, "poles": None, "failures": None}
        parts_before = n_parts(store)
        t0 = time.monotonic()
        proc = start(command(records, cov, store), logs / f"kill-{len(rows)}.log")
        time.sleep(max(0.0, t_kill - (time.monotonic() - t0)))
        if proc.poll() is not None:  # ended before the moment drawn (the machine was faster): draw again
            continue
        os.killpg(proc.pid, signal.SIGKILL)
        proc.wait()
        parts_at_kill = n_parts(store)
        killed_tmp = [p.name for p in trial.iterdir() if re.search(rf"\.(tmp|old)-{proc.pid}$", p.name)]
        row = {"kind": kind, "mode": mode, "t": t_kill, "of": seconds, "late": late,
               "write_phase": parts_at_kill == N_RECORDS, "temporaries_at_kill": killed_tmp,
               "parts": f"{parts_before}->{parts_at_kill}", "problems": []}
        # no unreadable store at any moment: absent (nothing written yet) or readable and old or new
        if not store.exists():
            row["store"] = "absent"
            if before["store"] is not None:
                row["problems"].append("store absent although a previous one existed"
                                       + (f" ({', '.join(killed_tmp)} beside it)" if killed_tmp else ""))
        else:
            try:
                ds = read_store(store)
            except Exception as exc:  # noqa: BLE001 - any failure to read is the finding
                row["store"] = "UNREADABLE"
                row["problems"].append(f"unreadable store: {type(exc).__name__}: {exc}")
            else:
                if identical(ds, ref["final"]["store"]):
                    row["store"] = "new"
                elif before["store"] is not None and identical(ds, before["store"]):
                    row["store"] = "old"
                else:
                    row["store"] = "OTHER"
                    row["problems"].append("store readable but neither the previous nor the final one")
        for name, path in tables(store).items():
            got = path.read_bytes() if path.exists() else None
            if got not in (before[name], ref["final"][name]):
                what = "absent" if got is None else f"{len(got)} bytes"
                row["problems"].append(f"{path.name} neither old nor new ({what})")
        row["unreadable"] = row["store"] == "UNREADABLE"
        # the resume: to completion, the reference store and tables, nothing left over
        code, _, text = run(command(records, cov, store), logs / f"resume-{len(rows)}.log")
        row["resume_code"] = code
        row["identical"] = False
        if code != 0:
            row["problems"].append(f"resume exit {code}: {text.strip().splitlines()[-1:]}")
        else:
            got = snapshot(trial, store)
            row["identical"] = (identical(got["store"], ref["final"]["store"])
                                and got["poles"] == ref["final"]["poles"]
                                and got["failures"] == ref["final"]["failures"])
            if not row["identical"]:
                row["problems"].append("resume not identical to the uninterrupted run")
        row["left"] = leftovers(trial, store)
        if row["left"]:
            row["problems"].append(f"left after the resume: {row['left']}")
        rows.append(row)
        say(f"  {kind:4} kill {len(rows):2}/{n} {mode:6} at {t_kill:5.2f} s of {seconds:4.1f} "
            f"({where:9}) parts {row['parts']:6} "
            f"{'write phase' if row['write_phase'] else 'records    '} store {row['store']:10} "
            f"temporaries {','.join(killed_tmp) or '-':24} resume {'identical' if row['identical'] else 'DIFFERS'}"
            + (f"  PROBLEMS: {row['problems']}" if row["problems"] else ""))
        if row["problems"]:
            keep = base / f"failed-kill-{len(rows)}"
            shutil.copytree(trial, keep, symlinks=True, dirs_exist_ok=True)
    return rows


# ---- 2. two runs at once ---------------------------------------------------------------------------------------


def concurrent(kind: str, base: Path, records: list, cov: str, ref: dict, rounds: int) -> list:
    results = []
    for r in range(rounds):
        folder = base / "concurrent"
        reset(folder, None)
        store = folder / f"tracks.{kind}"
        lock = folder / "tracks.lock"
        first = start(command(records, cov, store), base / f"concurrent-{r}-first.log")
        deadline = time.monotonic() + 120
        while first.poll() is None and time.monotonic() < deadline:  # until the first holds the lock
            if lock.exists() and str(first.pid) in lock.read_text(errors="replace"):
                break
            time.sleep(0.02)
        extra = ("--no-resume",) if r % 2 else ()
        code2, _, text2 = run(command(records, cov, store, *extra), base / f"concurrent-{r}-second.log")
        code1 = first.wait()
        problems = []
        if code2 != 2:
            problems.append(f"second run exit {code2}, not 2")
        if str(first.pid) not in text2:
            problems.append("second run's message does not name the holder's pid")
        if code1 != 0:
            problems.append(f"first run exit {code1}")
        else:
            got = snapshot(folder, store)
            if not (identical(got["store"], ref["final"]["store"]) and got["poles"] == ref["final"]["poles"]
                    and got["failures"] == ref["final"]["failures"]):
                problems.append("first run's store differs from the uninterrupted run's")
        left = leftovers(folder, store)
        if left:
            problems.append(f"left: {left}")
        message = next((line for line in text2.splitlines() if "in use" in line), text2.strip()[-200:])
        say(f"  {kind:4} concurrent round {r + 1}: second run{' --no-resume' if extra else ''} exit {code2}: "
            f"{message[:160]}" + (f"  PROBLEMS: {problems}" if problems else ""))
        results.append({"kind": kind, "problems": problems})
    return results


# ---- 3. full disk -----------------------------------------------------------------------------------------------


def full_disk(kind: str, base: Path, records: list, cov: str, ref: dict) -> dict | None:
    if os.geteuid() != 0:
        say(f"  {kind:4} full disk: skipped (not root: cannot mount a tmpfs)")
        return None
    mnt = base / "tmpfs"
    mnt.mkdir(exist_ok=True)
    mounted = subprocess.run(["mount", "-t", "tmpfs", "-o", "size=16m", "tmpfs", str(mnt)],
                             capture_output=True, text=True)
    if mounted.returncode != 0:
        say(f"  {kind:4} full disk: skipped (mount -t tmpfs failed: {mounted.stderr.strip()})")
        return None
    problems = []
    try:
        out = mnt / "out"
        shutil.copytree(base / "previous", out, symlinks=True)  # the store of 8 records ...
        store = out / f"tracks.{kind}"
        # ... and the parts of all 12: the run only writes
        shutil.copytree(base / "reference" / "tracks.parts", out / "tracks.parts", dirs_exist_ok=True)
        tables(store)["failures"].unlink()  # to see that it is written
        filler = mnt / "filler"
        with open(filler, "wb", buffering=0) as fh:  # fill the disk, then give back 16 kB
            for chunk in (1 << 20, 4096):
                try:
                    while True:
                        fh.write(bytes(chunk))
                except OSError:
                    pass
        size = filler.stat().st_size
        os.truncate(filler, size - size % 4096 - 16384)  # room for the failures table, not for a store
        free = shutil.disk_usage(mnt).free
        code, _, text = run(command(records, cov, store), base / "full-disk.log")
        error = next((line for line in text.splitlines() if "cannot write" in line or "No space" in line), "")
        if code != 2:
            problems.append(f"exit {code}, not 2")
        if not re.search(rf"{re.escape(str(out))}/tracks\.", error):
            problems.append(f"error does not name an output path: {error!r}")
        try:
            still = read_store(store)
            if not identical(still, ref["previous"]["store"]):
                problems.append("previous store changed")
        except Exception as exc:  # noqa: BLE001
            problems.append(f"previous store unreadable: {exc}")
        if tables(store)["poles"].read_bytes() != ref["previous"]["poles"]:
            problems.append("previous pole table changed")
        failures_written = tables(store)["failures"].exists()
        if not failures_written:
            problems.append("failures table not written")
        left = leftovers(out, store)
        if left:
            problems.append(f"left: {left}")
        filler.unlink()
        code2, _, _ = run(command(records, cov, store), base / "full-disk-resume.log")
        got = snapshot(out, store)
        resumed = (code2 == 0 and identical(got["store"], ref["final"]["store"])
                   and got["poles"] == ref["final"]["poles"])
        if not resumed:
            problems.append("the run after freeing space is not the uninterrupted run")
        say(f"  {kind:4} full disk ({free // 1024} kB free): exit {code}: {error[:170]}; previous store "
            f"{'intact' if 'previous store changed' not in problems else 'CHANGED'}, failures table "
            f"{'written' if failures_written else 'MISSING'}; after freeing space: "
            f"{'identical' if resumed else 'DIFFERS'}" + (f"  PROBLEMS: {problems}" if problems else ""))
    finally:
        if subprocess.run(["umount", str(mnt)], capture_output=True).returncode != 0:
            subprocess.run(["umount", "-l", str(mnt)], check=False)  # busy: detach it all the same
    return {"kind": kind, "problems": problems}


# ---- main -------------------------------------------------------------------------------------------------------


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--kills", type=int, default=30, help="kills per store format (default 30)")
    parser.add_argument("--rounds", type=int, default=3, help="rounds of two runs at once per format (default 3)")
    parser.add_argument("--seed", type=int, default=26, help="seeds the simulation and the kill moments")
    parser.add_argument("--formats", nargs="+", default=["nc", "zarr"], choices=["nc", "zarr"])
    parser.add_argument("--no-disk", action="store_true", help="skip the full-disk round")
    parser.add_argument("--work", type=Path, help="working folder (default: a temporary one, removed if all passed)")
    args = parser.parse_args(argv)
    work = args.work or Path(tempfile.mkdtemp(prefix="modaluq-faults-"))
    work.mkdir(parents=True, exist_ok=True)
    probe = subprocess.run([sys.executable, "-c", "import modaluq; print(modaluq.__file__, modaluq.__version__)"],
                           env=ENV, capture_output=True, text=True)
    say(f"fault campaign: seed {args.seed}, {args.kills} kills per format, package {probe.stdout.strip()}, "
        f"work folder {work}")
    records, cov = simulate(work, args.seed)
    rng = random.Random(args.seed)
    summary, other = [], []
    t_start = time.monotonic()
    for kind in args.formats:
        base = work / kind
        base.mkdir(exist_ok=True)
        ref = reference(kind, base, records, cov)
        f, u = ref["fresh"], ref["update"]
        say(f"{kind}: uninterrupted run {f['seconds']:.1f} s (all records done at {f['all_parts']:.1f} s, "
            f"first output temporary at {f['write']:.1f} s); 4 records added to a store of 8: "
            f"{u['seconds']:.1f} s (all done at {u['all_parts']:.1f} s, first temporary at {u['write']:.1f} s)")
        rows = kills(kind, base, records, cov, ref, args.kills, rng)
        summary.append((kind, rows))
        other += concurrent(kind, base, records, cov, ref, args.rounds)
        if not args.no_disk:
            disk = full_disk(kind, base, records, cov, ref)
            if disk is not None:
                other.append(disk)
    say(f"\nsummary ({time.monotonic() - t_start:.0f} s)")
    say("| store | kills | in the last 20 % | in the write phase (all records done) | with a temporary of the "
        "killed run | store absent / old / new after the kill | unreadable at any moment | resumed identical "
        "| temporaries left |")
    say("|---|---|---|---|---|---|---|---|---|")
    bad = 0
    for kind, rows in summary:
        count = {s: sum(r["store"] == s for r in rows) for s in ("absent", "old", "new")}
        say(f"| {kind} | {len(rows)} | {sum(r['late'] for r in rows)} | {sum(r['write_phase'] for r in rows)} "
            f"| {sum(bool(r['temporaries_at_kill']) for r in rows)} | {count['absent']} / {count['old']} / "
            f"{count['new']} | {sum(r['unreadable'] for r in rows)} | {sum(r['identical'] for r in rows)} "
            f"| {sum(bool(r['left']) for r in rows)} |")
        bad += sum(bool(r["problems"]) for r in rows)
    bad += sum(bool(o["problems"]) for o in other)
    say(f"concurrent rounds and full-disk rounds: {len(other)}, with problems: "
        f"{sum(bool(o['problems']) for o in other)}")
    if bad:
        say(f"{bad} trial(s) with problems; their folders are kept in {work}")
        return 1
    if args.work is None:
        shutil.rmtree(work, ignore_errors=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
