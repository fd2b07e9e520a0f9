"""Outputs before and after a refactoring: the same commands, the same bytes where it matters.

A refactoring must not change what users get. This runs the command line as the tutorial and
the monitoring guide do (docs/tutorial.md §2 and §9, docs/monitoring.md §7), once on the old code
and once on the new, and compares everything written: JSON bar the time stamp, CSV byte for byte,
NetCDF data and attributes (bar time stamps), PNG pixels, and the printed report.

    python scripts/refactor_check.py run  OUT_DIR     # with the package on the path (e.g. .venv)
    python scripts/refactor_check.py compare OLD_DIR NEW_DIR

Takes about two minutes a run (the wind-turbine record and two monitoring folders).
"""

from __future__ import annotations

import json
import os
import pathlib
import re
import subprocess
import sys

DATA = pathlib.Path(__file__).resolve().parents[2] / "shared" / "data"
TURBINE = DATA / "owi_offshore_wind_turbine_tower_2020.tdms"


def _cli(out: pathlib.Path, name: str, *args: str) -> None:
    """Run ``modaluq ARGS`` in ``out`` and keep its stdout and stderr (the report a user reads)."""
    # the records were just written: complete (a monitoring run leaves files modified in the last
    # seconds for later; older versions ignore the variable)
    env = {**os.environ, "MODALUQ_SETTLE_SECONDS": "0"}
    proc = subprocess.run([sys.executable, "-m", "modaluq.cli", *args], cwd=out, capture_output=True, text=True,
                          env=env)
    (out / f"{name}.stdout").write_text(proc.stdout)
    (out / f"{name}.stderr").write_text(proc.stderr)
    (out / f"{name}.status").write_text(str(proc.returncode))


def run(out: pathlib.Path) -> None:
    import numpy as np

    import modaluq

    out.mkdir(parents=True, exist_ok=True)
    # tutorial §1-2: the chain as CSV, input/output
    sim = modaluq.simulate(100_000, seed=1)
    t = np.arange(sim.n_samples) / sim.fs
    np.savetxt(out / "chain.csv", np.column_stack([t, sim.y, sim.u]), delimiter=",", fmt="%.10g",
               header="time [s],acc1 [m/s^2],acc2 [m/s^2],acc5 [m/s^2],force [N]", comments="")
    _cli(out, "chain", "identify", "chain.csv", "--inputs", "force", "--block-rows", "25", "--orders", "2:60:2",
         "--plot", "diagram.png", "--out", "modes.json", "--out", "modes.csv", "--out", "diagram.nc")
    _cli(out, "chain_oo", "identify", "chain.csv", "--outputs", "acc1", "acc2", "acc5", "--block-rows", "25",
         "--orders", "2:60:2", "--out", "modes_oo.json")
    # tutorial §9: the wind turbine's raw TDMS, automatic settings
    _cli(out, "turbine", "identify", str(TURBINE), "--frequency-range", "0.2", "5", "--plot", "turbine.png",
         "--plot-shapes", "turbine_shapes.png", "--out", "turbine.json", "--out", "turbine.nc")
    # monitoring: the simulator's folder with a covariate table, and the turbine cut in five records
    campaign = modaluq.simulate_monitoring(24, n_samples=10_000, seed=4, damage_element=2, damage_record=16,
                                           damage_fraction=0.05)
    campaign.write(out / "monitor_sim", format="npz", covariates=out / "monitor_sim.covariates.csv")
    _cli(out, "monitor_sim", "monitor", "monitor_sim", "--out", "sim_tracks.nc", "--covariates",
         "monitor_sim.covariates.csv", "--reference-records", "10", "--no-progress", "--threads", "1",
         "--plot", "sim_tracks.png", "--poles", "sim_poles.csv")
    from nptdms import ChannelObject, TdmsFile, TdmsWriter

    records = out / "monitor_turbine"
    records.mkdir(exist_ok=True)
    group = TdmsFile.read(TURBINE)["acceleration"]
    channels = list(group.channels())
    dt = channels[0].properties["wf_increment"]
    n = int(round(120 / dt))
    start = np.datetime64("2020-04-09T22:00:00")
    for k in range(len(channels[0]) // n):
        stamp = str(start + np.timedelta64(120 * k, "s")).replace(":", "-").replace("T", "_")
        with TdmsWriter(records / f"BB-C01_{stamp}.tdms") as w:
            w.write_segment([ChannelObject("acceleration", c.name, np.asarray(c[k * n:(k + 1) * n]),
                                           properties={"wf_increment": dt, "unit_string": "g"}) for c in channels])
    _cli(out, "monitor_turbine", "monitor", "monitor_turbine", "--out", "turbine_tracks.nc", "--frequency-range",
         "0.2", "5", "--reference-records", "3", "--no-progress", "--threads", "1", "--plot", "turbine_tracks.png")


#: keys whose values differ between two runs by design (when, how long); paths are made relative
VOLATILE = ("created_utc", "elapsed_s", "seconds")


def _strip_json(x, root: str):
    """JSON without what differs between two runs by design: time stamps, durations, the run's folder."""
    if isinstance(x, dict):
        return {k: _strip_json(v, root) for k, v in x.items() if k not in VOLATILE}
    if isinstance(x, list):
        return [_strip_json(v, root) for v in x]
    if isinstance(x, str):
        return x.replace(root, "<run>")
    return x


def _strip_text(text: str, root: str) -> str:
    """A printed report without the run's folder and its durations ("(2.9 s)", "3.2 s)")."""
    return re.sub(r"\d+(\.\d+)? s\)", "<t> s)", text.replace(root, "<run>"))


def compare(old: pathlib.Path, new: pathlib.Path) -> int:
    import numpy as np
    import xarray as xr
    from matplotlib.image import imread

    problems, checked = [], 0
    # part files are named by a hash of the record's path: compare their contents as a set
    for parts in sorted(old.glob("*.parts")):
        checked += 1
        contents = [sorted(json.dumps(_strip_json(json.loads(p.read_text()), str(run)), sort_keys=True)
                           for p in (run / parts.name).glob("*.json")) for run in (old, new)]
        if contents[0] != contents[1]:
            problems.append(f"{parts.name}: part files differ")
    for a in sorted(p for p in old.rglob("*") if p.is_file() and ".parts" not in p.parent.name):
        rel = a.relative_to(old)
        b = new / rel
        if not b.exists():
            problems.append(f"{rel}: missing in {new}")
            continue
        checked += 1
        if a.suffix == ".json":
            if _strip_json(json.loads(a.read_text()), str(old)) != _strip_json(json.loads(b.read_text()), str(new)):
                problems.append(f"{rel}: JSON differs")
        elif a.suffix == ".nc":
            da, db = xr.open_dataset(a), xr.open_dataset(b)
            try:
                for ds in (da, db):
                    ds.attrs.pop("stamp", None)
                    ds.attrs.pop("created", None)
                xr.testing.assert_identical(da, db)
            except AssertionError as exc:
                problems.append(f"{rel}: NetCDF differs: {str(exc)[:400]}")
            finally:
                da.close()
                db.close()
        elif a.suffix == ".png":
            ia, ib = imread(a), imread(b)
            if ia.shape != ib.shape or not np.array_equal(ia, ib):
                problems.append(f"{rel}: PNG pixels differ")
        elif a.suffix in (".stdout", ".stderr"):
            if _strip_text(a.read_text(), str(old)) != _strip_text(b.read_text(), str(new)):
                problems.append(f"{rel}: printed report differs")
        elif a.read_bytes() != b.read_bytes():
            problems.append(f"{rel}: bytes differ")
    for p in problems:
        print("DIFF", p)  # noqa: T201 (a script: its report is its output)
    print(f"{checked} files compared, {len(problems)} differ")  # noqa: T201
    return 1 if problems else 0


if __name__ == "__main__":
    if len(sys.argv) == 3 and sys.argv[1] == "run":
        run(pathlib.Path(sys.argv[2]).resolve())
    elif len(sys.argv) == 4 and sys.argv[1] == "compare":
        sys.exit(compare(pathlib.Path(sys.argv[2]), pathlib.Path(sys.argv[3])))
    else:
        sys.exit(__doc__)
