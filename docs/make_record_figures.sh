#!/usr/bin/env bash
# The figures of docs/settings.md ("The shared records from the command line") and of
# docs/tutorial.md §9: `modaluq identify` run on each shared record the way an engineer would:
# the file, the channels (and the inputs the file declares), a band, and the time window where
# the data README asks for one. Nothing else is set: every other setting is chosen from the data.
#
# Writes docs/img/cli_<record>.png (stabilization diagram over the output spectrum),
# docs/img/cli_<record>_shapes.png (mode shapes with ±1σ) for the records whose shapes are worth
# a look, and /tmp/cli_<record>.json (the report) and /tmp/cli_<record>.txt (the printed output).
# Prints each run's noise floor, modes, harmonic flags and largest dropped clusters; the
# warnings of each run go to stderr as they come.
#
# Usage (from the repository root): bash docs/make_record_figures.sh [DATA_DIR]   (default ../shared/data)
# About 20 s on one core.
set -euo pipefail
data=${1:-../shared/data}
out=docs/img
export OPENBLAS_NUM_THREADS=${OPENBLAS_NUM_THREADS:-1}
[[ -d $data ]] || { echo "make_record_figures.sh: no data directory '$data'" >&2; exit 2; }
[[ -d $out ]] || { echo "make_record_figures.sh: run from the repository root (no $out)" >&2; exit 2; }

run() {  # name, shapes|noshapes, file, options...
  local name=$1 shapes=$2 file=$3; shift 3
  local extra=()
  [[ $shapes == shapes ]] && extra=(--plot-shapes "$out/cli_${name}_shapes.png")
  echo "== $name: modaluq identify $file $*"
  modaluq identify "$data/$file" "$@" --no-progress --overwrite --plot "$out/cli_$name.png" \
    ${extra[@]+"${extra[@]}"} --out "/tmp/cli_$name.json" > "/tmp/cli_$name.txt"
  sed -n '/noise floor/p; /modes (std/,$p' "/tmp/cli_$name.txt"
  echo
}

# simulated, with reference values (data README §1, §2): all channels, output-only
run koma_frame shapes koma_shearframe_sim.npz --frequency-range 0.1 1.5
run bridge shapes ssicov_lysefjord_bridge_sim.npz --frequency-range 0.15 1.5
# the README's recommended_slice is y[2000:18384, 2]: the vertical channel, samples 2000..18384
# at 425.08 Hz (4.705-43.248 s; the operator touched the phone outside them)
run slab noshapes cessipy_smartphone_slab.npz --outputs phone_Z_vertical --start 4.705 --stop 43.248 \
  --frequency-range 10 30
# earthquakes: the .npz declares the ground channels as inputs (u); all deck channels are outputs
run meloland shapes cesmd_meloland_overpass_2016.npz --frequency-range 1 20
run painter_street shapes cesmd_painter_st_overpass_2016.npz --frequency-range 1 15
# raw TDMS, one group of 8 accelerometers (in g); fs from wf_increment
run wind_turbine shapes owi_offshore_wind_turbine_tower_2020.tdms --frequency-range 0.2 5
# the monitoring record's vibration group (its other group holds slow ambient covariates)
run sensor_array shapes owi_sensor_array_with_ambient_2022.tdms --read-option group=acceleration \
  --frequency-range 1 60
