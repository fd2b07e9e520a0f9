#pragma once
/// @file version.hpp
/// Single source of the modaluq version (read by CMake and by scikit-build-core).

#define MODALUQ_VERSION_MAJOR 0
#define MODALUQ_VERSION_MINOR 1
#define MODALUQ_VERSION_PATCH 0
#define MODALUQ_VERSION_STRING "0.1.0"

namespace modaluq {
/// The library version, "major.minor.patch".
inline constexpr const char* version = MODALUQ_VERSION_STRING;
}  // namespace modaluq
