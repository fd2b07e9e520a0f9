#!/usr/bin/env bash
# Set up modaluq from this clone on a Debian/Ubuntu machine: the system packages it builds
# with (apt-get, as root or through sudo), a virtual environment .venv/ beside this file's
# folder (Debian's Python refuses `pip install` outside one), and the package in it.
#
#   bash scripts/setup.sh            # the package with plots, loaders and exports
#   bash scripts/setup.sh --test     # the same plus what the tests need (doctest, pytest, ...)
#
# Environment: MODALUQ_VENV (default .venv), PYTHON (default python3),
# MODALUQ_NATIVE=ON to compile for this machine's CPU only (-march=native; the default build
# runs on any x86-64/arm64 CPU, so a wheel copied to another machine does not die of SIGILL: on
# x86-64 it compiles the core for the baseline and for x86-64-v3 (AVX2/FMA) and `import modaluq`
# runs the one the CPU supports; MODALUQ_CPU=baseline forces the baseline), MODALUQ_DISPATCH=OFF
# to compile the baseline core only (half the build's time; the core then runs 1.2-1.5x slower).
set -euo pipefail
cd "$(dirname "$0")/.."
extras="plot,io,export,monitor,report"
apt_pkgs=(g++ make cmake python3-venv python3-dev libeigen3-dev libopenblas-dev)
if [[ "${1:-}" == "--test" ]]; then
  extras="all"
  # chromium: the HTML report's browser test (tests/python/test_htmlreport.py; Debian's package, headless);
  # fonts-dejavu-core: text in its screenshots
  # clang, libclang-rt-dev: the sanitizer build of the C++ tests (tests/run.sh; about 2x faster to compile than GCC)
  apt_pkgs+=(doctest-dev chromium fonts-dejavu-core clang libclang-rt-dev)
fi

missing=()
for p in "${apt_pkgs[@]}"; do dpkg -s "$p" >/dev/null 2>&1 || missing+=("$p"); done
if ((${#missing[@]})); then
  echo "== system packages: ${missing[*]}"
  sudo_cmd=()
  if [[ $(id -u) -ne 0 ]]; then sudo_cmd=(sudo); fi
  export DEBIAN_FRONTEND=noninteractive
  "${sudo_cmd[@]}" apt-get update -q >/dev/null
  "${sudo_cmd[@]}" apt-get install -y -q --no-install-recommends "${missing[@]}" >/dev/null
fi

venv="${MODALUQ_VENV:-.venv}"
python="${PYTHON:-python3}"
if [[ ! -x "$venv/bin/python" ]]; then
  echo "== virtual environment $venv ($("$python" --version))"
  "$python" -m venv "$venv"
fi
"$venv/bin/python" -m pip install -q --upgrade pip

# The C++ extension takes minutes to compile (on a fresh Debian machine, a peak of ~4.3 GB of memory
# with several compilers at once, single steps of 6-9 minutes: README.md); show its steps and a
# heartbeat instead of minutes of silence, and keep the whole log for when it fails.
log="$venv/modaluq-build.log"
echo "== building and installing modaluq[$extras] (the C++ extension takes several minutes; log: $log)"
# on x86-64 the core is compiled twice, _core_baseline and _core_x86_64_v3 (bindings/CMakeLists.txt)
defines=()  # CMake options of the build
if [[ "${MODALUQ_NATIVE:-OFF}" == "ON" ]]; then defines=(-Ccmake.define.MODALUQ_NATIVE=ON); fi
if [[ "${MODALUQ_DISPATCH:-ON}" == "OFF" ]]; then defines+=(-Ccmake.define.MODALUQ_DISPATCH=OFF); fi
# The build tools live in the venv and the build reuses build/ (pyproject.toml's build-dir), so
# a second run recompiles only what changed (with pip's isolated build environments the include
# paths change every time and everything is rebuilt).
"$venv/bin/python" -m pip install -q "scikit-build-core>=0.10" "pybind11>=2.11" ninja
: >"$log"  # exists before tail follows it, and holds only this build
"$venv/bin/python" -m pip install -v --no-build-isolation ".[$extras]" "${defines[@]}" >"$log" 2>&1 </dev/null &
pid=$!
# Heartbeat: one compile step can run for minutes without a line of its own.
started=$(date +%s)
(
  while sleep 30 && kill -0 "$pid" 2>/dev/null; do
    elapsed=$(( $(date +%s) - started ))
    printf '   ... still compiling (%d min %02d s)\n' $((elapsed / 60)) $((elapsed % 60))
  done
) &
heartbeat=$!
trap 'kill "$pid" "$heartbeat" 2>/dev/null' EXIT  # a killed setup leaves no compiler running
# Progress: the build's own [k/n] lines as they appear.
tail -n +1 -f "$log" --pid="$pid" 2>/dev/null | grep --line-buffered -E '^\s*\[ *[0-9]+(/[0-9]+|%)\] (Building|Linking)' \
  | sed -u -E 's/^\s*/   /; s/ (CXX|object|shared module) / /g' || true
status=0
wait "$pid" || status=$?
kill "$heartbeat" 2>/dev/null || true
wait "$heartbeat" 2>/dev/null || true
if ((status)); then
  trap - EXIT
  echo "pip install failed; the last lines of $log:" >&2
  tail -n 40 "$log" >&2
  exit 1
fi
trap - EXIT
echo "== installed: $("$venv/bin/python" -c 'import modaluq, modaluq.buildinfo as b; print("modaluq", modaluq.__version__, "(C++ core:", b.core_summary() + ")")') in $venv"
