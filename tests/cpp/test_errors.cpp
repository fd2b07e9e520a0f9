// errors.hpp: the typed exceptions and the message builders every check uses.
#include <doctest/doctest.h>

#include <modaluq/errors.hpp>

#include <stdexcept>
#include <string>

// One namespace per test file: the unity build (tests/cpp/CMakeLists.txt) compiles several files as one.
namespace test_errors {

TEST_CASE("invalid_argument is a std::invalid_argument, numerical_error a std::runtime_error") {
    CHECK_THROWS_AS(modaluq::detail::fail("x"), std::invalid_argument);
    CHECK_THROWS_AS(modaluq::detail::fail("x"), modaluq::invalid_argument);
    CHECK_THROWS_WITH(modaluq::detail::fail("block_rows must be >= 2, got ", 1), "block_rows must be >= 2, got 1");
    CHECK_THROWS_AS(throw modaluq::numerical_error("eig"), std::runtime_error);
    // require() throws only when its condition is false, with the parts joined
    CHECK_NOTHROW(modaluq::detail::require(true, "never"));
    CHECK_THROWS_WITH(modaluq::detail::require(false, "n_blocks = ", 3, ", fs = ", 2.5), "n_blocks = 3, fs = 2.5");
}

}  // namespace test_errors
