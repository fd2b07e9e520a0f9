#!/usr/bin/env bash
# The figures of docs/settings.md ("The shared records from the command line"): `modaluq identify`
# run on each shared record the way an engineer would (the file, the channels, a band), writing
# the stabilization diagram to docs/img/cli_<record>.png and the report to /tmp/cli_<record>.json.
# Usage (from the repository root): bash docs/make_record_figures.sh [DATA_DIR]   (default ../shared/data)
set -euo pipefail
data=${1:-../shared/data}
out=docs/img
run() {  # name, file, options...
  local name=$1 file=$2; shift 2
  echo "== $name: modaluq identify $(basename "$file") $*"
  modaluq identify "$data/$file" "$@" --no-progress --overwrite \
    --plot "$out/cli_$name.png" --out "/tmp/cli_$name.json" | sed -n '/modes (std/,$p'
}
run koma_frame koma_shearframe_sim.npz --frequency-range 0.1 1.5
run bridge ssicov_lysefjord_bridge_sim.npz --frequency-range 0.15 1.5
# the source analyses samples 2000..18384 (4.71-43.25 s): the operator touched the phone outside
run slab cessipy_smartphone_slab.npz --frequency-range 10 30 --start 4.705 --stop 43.25
# ground motion as input (the .npz declares it); all deck channels
run meloland cesmd_meloland_overpass_2016.npz --frequency-range 1 20
run painter_street cesmd_painter_st_overpass_2016.npz --frequency-range 1 15
run wind_turbine owi_offshore_wind_turbine_tower_2020.tdms --frequency-range 0.2 5
# the monitoring record's vibration group (its other group holds slow ambient covariates)
run sensor_array owi_sensor_array_with_ambient_2022.tdms --read-option group=acceleration --frequency-range 1 60
