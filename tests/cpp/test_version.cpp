// version.hpp: one version, in the numbers and in the string.
#include <doctest/doctest.h>

#include <modaluq/version.hpp>

#include <string>

TEST_CASE("version is single-sourced") {
    CHECK(std::string(modaluq::version) == MODALUQ_VERSION_STRING);
    CHECK(std::string(modaluq::version) ==
          std::to_string(MODALUQ_VERSION_MAJOR) + "." + std::to_string(MODALUQ_VERSION_MINOR) + "." +
              std::to_string(MODALUQ_VERSION_PATCH));
}
