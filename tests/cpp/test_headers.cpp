#include <doctest/doctest.h>

#include "eigen_instances.hpp"

#include <modaluq/modaluq.hpp>

#include <string>

TEST_CASE("version is single-sourced") {
    CHECK(std::string(modaluq::version) == MODALUQ_VERSION_STRING);
    CHECK(std::string(modaluq::version) ==
          std::to_string(MODALUQ_VERSION_MAJOR) + "." + std::to_string(MODALUQ_VERSION_MINOR) + "." +
              std::to_string(MODALUQ_VERSION_PATCH));
}

TEST_CASE("invalid_argument is a std::invalid_argument") {
    CHECK_THROWS_AS(modaluq::detail::fail("x"), std::invalid_argument);
    CHECK_THROWS_WITH(modaluq::detail::fail("block_rows must be >= 2, got ", 1), "block_rows must be >= 2, got 1");
}
