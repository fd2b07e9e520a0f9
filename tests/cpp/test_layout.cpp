// layout.hpp: the sizes of the Hankel covariances and the largest order, from p, q, l, m, r.
#include <doctest/doctest.h>

#include <modaluq/layout.hpp>

#include <stdexcept>

// One namespace per test file: the unity build (tests/cpp/CMakeLists.txt) compiles several files as one.
namespace test_layout {

TEST_CASE("layout sizes follow from the horizons and channels") {
    modaluq::HankelLayout L;
    L.n_outputs = 3;
    L.n_inputs = 1;
    L.block_rows = 10;
    L.past_block_rows = 0;  // q = p
    L.validate();
    CHECK(L.q() == 10);
    CHECK(L.window() == 20);
    CHECK(L.max_lag() == 19);
    CHECK(L.rows_future() == 30);  // a = p l
    CHECK(L.rows_past() == 30);    // b = q r, r = l
    CHECK(L.rows_input() == 10);   // p m
    CHECK(L.n_covariance_entries() == 30 * 30 + 30 * 10 + 10 * 10 + 30 * 10);
    CHECK(L.max_order() == 27);  // min((p-1) l, q r) = min(27, 30)
    L.references = {2};
    L.past_block_rows = 8;
    L.validate();
    CHECK(L.n_references() == 1);
    CHECK(L.reference(0) == 2);
    CHECK(L.max_order() == 8);  // min(27, 8 * 1)
}

TEST_CASE("layout errors name the field") {
    modaluq::HankelLayout L;
    L.n_outputs = 2;
    L.block_rows = 1;
    CHECK_THROWS_WITH_AS(L.validate(), "block_rows must be >= 2, got 1", std::invalid_argument);
    L.block_rows = 4;
    L.references = {0, 0};
    CHECK_THROWS_WITH_AS(L.validate(), "references: index 0 is repeated", std::invalid_argument);
    L.references = {5};
    CHECK_THROWS_WITH_AS(L.validate(), "references: index 5 is out of range for 2 outputs", std::invalid_argument);
}

}  // namespace test_layout
