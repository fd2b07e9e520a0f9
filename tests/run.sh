#!/usr/bin/env bash
# Set up and run every test of modaluq on a Debian/Ubuntu machine (the command CI runs):
#   1. scripts/setup.sh --test: system packages, the virtual environment .venv, the package;
#   2. the C++ core's tests (ctest), built (with Clang when installed) with assertions on and
#      AddressSanitizer + UndefinedBehaviorSanitizer, so a read out of bounds or an overflow fails the run; the
#      build also compiles every header on its own (MODALUQ_CHECK_HEADERS, tests/cpp);
#   3. a C++ project built against the installed headers (cpp/examples);
#   4. ruff, then pytest (oracle cross-validation, Monte Carlo, loaders, CLI, the layers of the
#      package, the docstring examples; every warning is an error unless a test expects it);
#   5. a short fuzz run over the file loaders (tests/fuzz; FUZZ_SECONDS per format, default 10;
#      failing inputs are saved in build/fuzz-failures).
# Idempotent. JOBS sets the build parallelism (default 2).
set -euo pipefail
cd "$(dirname "$0")/.."
JOBS=${JOBS:-2}
start=$SECONDS
stage() { echo "== $1   [$((SECONDS - start)) s since the start]"; }  # where CI's time goes
stage "setup: system packages, .venv, the package"
bash scripts/setup.sh --test
PY="${MODALUQ_VENV:-.venv}/bin/python"

stage "C++ core: build (assertions, ASan, UBSan) and ctest"
san="-fsanitize=address,undefined -fno-sanitize-recover=all -fno-omit-frame-pointer"
# Clang when installed (scripts/setup.sh --test installs it): its front end instantiates the core's
# Eigen templates about 2x faster than GCC's, which halves this stage. GCC builds the Python module,
# whose numbers pytest checks, so both compilers see the core. SANITIZE_CXX overrides.
cxx="${SANITIZE_CXX:-$(command -v clang++ || command -v g++)}"
echo "   compiler: $("$cxx" --version | head -n 1)"
cmake -S . -B build/cpp-sanitize -DCMAKE_BUILD_TYPE=Debug -DCMAKE_CXX_COMPILER="$cxx" -DCMAKE_CXX_FLAGS="$san" \
      -DCMAKE_EXE_LINKER_FLAGS="$san" >/dev/null
cmake --build build/cpp-sanitize -j"$JOBS"
ASAN_OPTIONS=detect_leaks=1:abort_on_error=0 UBSAN_OPTIONS=print_stacktrace=1 \
  ctest --test-dir build/cpp-sanitize --output-on-failure -j"$JOBS"

stage "CMake: modaluq as a subproject leaves the parent's build type, BLAS and tests alone"
cmake -S tests/cmake_subproject -B build/cmake-subproject >/dev/null

stage "C++ consumer project against the installed package"
cmake --install build/cpp-sanitize --prefix build/prefix >/dev/null
# the same compiler as the sanitizer build: the example compiles the whole pipeline (Clang 38 s, GCC ~2-4 min)
cmake -S cpp/examples -B build/example -DCMAKE_CXX_COMPILER="$cxx" -DCMAKE_PREFIX_PATH="$PWD/build/prefix" >/dev/null
cmake --build build/example -j"$JOBS"
build/example/identify_stream

stage "Python: ruff (lint) and pytest (tests and the package's docstring examples, warnings as errors)"
"$PY" -m ruff check python tests bench studies
"$PY" -m pytest -q --durations=15 --doctest-modules --pyargs modaluq tests/python

stage "loaders: short fuzz run (the long run: docs/reliability.md)"
"$PY" tests/fuzz/fuzz_loaders.py --seconds "${FUZZ_SECONDS:-10}" --seed "${FUZZ_SEED:-0}" --save-dir build/fuzz-failures
stage "done"
