#!/usr/bin/env bash
# Set up and run every test of modaluq: the C++ core (ctest), a downstream CMake project built
# against the installed headers, and the Python package (pytest). Idempotent; needs root for
# apt-get on a fresh Debian/Ubuntu machine.
set -euo pipefail
cd "$(dirname "$0")/.."
JOBS=${JOBS:-2}

# OpenBLAS is optional for the library; the tests and the Python module use it when present.
if ! dpkg -s libeigen3-dev doctest-dev libopenblas-dev >/dev/null 2>&1; then
  export DEBIAN_FRONTEND=noninteractive
  apt-get update -q && apt-get install -y -q --no-install-recommends libeigen3-dev doctest-dev libopenblas-dev
fi
python3 -m pip install -q --upgrade pip >/dev/null
python3 -m pip install -q ".[all]"

echo "== C++ core: build and ctest"
cmake -S . -B build/cpp -DCMAKE_BUILD_TYPE=Release >/dev/null
cmake --build build/cpp -j"$JOBS"
ctest --test-dir build/cpp --output-on-failure -j"$JOBS"

echo "== C++ consumer project against the installed package"
cmake --install build/cpp --prefix build/prefix >/dev/null
cmake -S cpp/examples -B build/example -DCMAKE_PREFIX_PATH="$PWD/build/prefix" >/dev/null
cmake --build build/example -j"$JOBS"
build/example/identify_stream

echo "== Python: pytest"
python3 -m pytest -q
