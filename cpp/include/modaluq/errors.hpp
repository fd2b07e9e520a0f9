#pragma once
/// @file errors.hpp
/// Exception types. Bad arguments throw modaluq::invalid_argument (a std::invalid_argument,
/// so pybind11 turns it into a Python ValueError); the message names the argument and the rule.
/// Numerical outcomes (rank deficiency, close singular values) are not exceptions: they are
/// reported in the result's status fields.

#include <sstream>
#include <stdexcept>
#include <string>
#include <utility>

namespace modaluq {

/// A precondition on an argument does not hold (shape, range, NaN/Inf, too-short record).
class invalid_argument : public std::invalid_argument {
public:
    using std::invalid_argument::invalid_argument;
};

/// A computation that cannot proceed on valid-looking input (e.g. a non-diagonalisable
/// state matrix). Rare; most numerical problems go to status flags instead.
class numerical_error : public std::runtime_error {
public:
    using std::runtime_error::runtime_error;
};

namespace detail {

inline constexpr double pi = 3.14159265358979323846;

template <class... Parts>
std::string concat(Parts&&... parts) {
    std::ostringstream os;
    (os << ... << std::forward<Parts>(parts));
    return os.str();
}

/// Throw modaluq::invalid_argument with a message assembled from the parts.
template <class... Parts>
[[noreturn]] void fail(Parts&&... parts) {
    throw invalid_argument(concat(std::forward<Parts>(parts)...));
}

/// Check a precondition; on failure throw invalid_argument with the message parts.
template <class... Parts>
void require(bool condition, Parts&&... parts) {
    if (!condition) fail(std::forward<Parts>(parts)...);
}

}  // namespace detail
}  // namespace modaluq
