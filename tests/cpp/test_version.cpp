// version.hpp: one version, in the numbers and in the string.
#include <doctest/doctest.h>

#include <modaluq/version.hpp>

#include <string>

// One namespace per test file: the unity build (tests/cpp/CMakeLists.txt) compiles several files as one.
namespace test_version {

TEST_CASE("version is single-sourced") {
    CHECK(std::string(modaluq::version) == MODALUQ_VERSION_STRING);
    CHECK(std::string(modaluq::version) ==
          std::to_string(MODALUQ_VERSION_MAJOR) + "." + std::to_string(MODALUQ_VERSION_MINOR) + "." +
              std::to_string(MODALUQ_VERSION_PATCH));
}

}  // namespace test_version
