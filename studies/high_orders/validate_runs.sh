#!/usr/bin/env bash
# Every Monte Carlo number of docs/validation.md "Above the true order" (issue 11), with the
# released command line.  Usage: bash studies/high_orders/validate_runs.sh OUT_DIR [RECORDS]
# About 25 min on 2 cores with 400 records.  Each case writes OUT_DIR/<case>/report.md etc.
set -euo pipefail
out=${1:?output directory}
n=${2:-400}
run() { local name=$1; shift; echo "== $name" >&2
        modaluq validate --records "$n" --no-progress --overwrite --out "$out/$name" "$@" > /dev/null; }
run chain            --order 12 18 24 36
run chain-known-only --order 12 18 24 36 --unknown-input-std 0
run chain-xi0.2      --order 12 24 36 --damping-ratio 0.002
run frame            --order 8 12 16 24 --n-dof 4 --input-dofs 0 3
run frame-known-only --order 8 12 16 24 --n-dof 4 --input-dofs 0 3 --unknown-input-std 0
for nb in 25 100 200; do
  run chain-nb$nb            --order 12 24 --n-blocks $nb
  run chain-known-only-nb$nb --order 12 24 --n-blocks $nb --unknown-input-std 0
done
