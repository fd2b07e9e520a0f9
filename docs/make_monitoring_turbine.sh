#!/usr/bin/env bash
# The measured check of docs/monitoring.md §7: the shared offshore wind turbine record (600 s of
# 8 tower accelerometers, raw TDMS) cut into five consecutive 120 s TDMS files named by their start
# time, as an acquisition system writing one file per interval would, then `modaluq monitor` over
# the folder with the first three as the reference period. Writes docs/img/monitoring_turbine.png
# and prints what the page quotes.
#
#   bash docs/make_monitoring_turbine.sh        # about a minute; needs .venv (scripts/setup.sh)
set -euo pipefail
cd "$(dirname "$0")/.."
PY="${MODALUQ_VENV:-.venv}/bin/python"
work=build/monitoring-turbine
rm -rf "$work" && mkdir -p "$work/records"
"$PY" - "$work/records" <<'EOF'
import sys
from pathlib import Path

import numpy as np
from nptdms import ChannelObject, TdmsFile, TdmsWriter

source = Path("../shared/data/owi_offshore_wind_turbine_tower_2020.tdms")
group = TdmsFile.read(source)["acceleration"]
channels = list(group.channels())
dt = channels[0].properties["wf_increment"]
n = int(round(120 / dt))
start = np.datetime64("2020-04-09T22:00:00")
for k in range(len(channels[0]) // n):
    t = start + np.timedelta64(120 * k, "s")
    name = Path(sys.argv[1]) / f"BB-C01_{str(t).replace(':', '-').replace('T', '_')}.tdms"
    with TdmsWriter(name) as w:
        w.write_segment([ChannelObject("acceleration", c.name, np.asarray(c[k * n:(k + 1) * n]),
                                       properties={"wf_increment": dt, "unit_string": "g"}) for c in channels])
    print("wrote", name)
EOF
"$PY" -m modaluq.cli monitor "$work/records" --out "$work/turbine_tracks.nc" --frequency-range 0.2 5 --settle-seconds 0 \
    --reference-records 3 --no-progress --plot docs/img/monitoring_turbine.png --dpi 90
