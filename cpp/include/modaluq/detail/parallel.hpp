#pragma once
/// @file detail/parallel.hpp
/// A minimal parallel loop over independent items (orders, blocks) with std::thread. Results
/// do not depend on the number of threads: each item is computed by the same code whichever
/// thread takes it, and items write to disjoint outputs.

#include <algorithm>
#include <atomic>
#include <exception>
#include <thread>
#include <vector>

#include "../layout.hpp"

namespace modaluq::detail {

/// Call fn(i) for i in [0, n), on up to `threads` threads (the calling thread is one of them).
/// Items are handed out in order, so put the most expensive first. The first exception thrown
/// by any item is rethrown here after every thread has stopped.
template <class Fn>
void parallel_for(Index n, Index threads, Fn&& fn) {
    const Index nt = std::max<Index>(1, std::min(threads, n));
    if (nt == 1) {
        for (Index i = 0; i < n; ++i) fn(i);
        return;
    }
    std::atomic<Index> next{0};
    std::vector<std::exception_ptr> errors(static_cast<size_t>(nt));
    auto worker = [&](Index w) {
        try {
            for (Index i = next++; i < n; i = next++) fn(i);
        } catch (...) {
            errors[static_cast<size_t>(w)] = std::current_exception();
            next = n;  // stop handing out work
        }
    };
    std::vector<std::thread> pool;
    pool.reserve(static_cast<size_t>(nt - 1));
    // A thread the OS refuses (limits, memory) is not an error: the threads already running
    // and the calling thread share the work, and the results are the same.
    // std::thread throws system_error, or bad_alloc for its state; either way fewer threads run.
    try {
        for (Index w = 1; w < nt; ++w) pool.emplace_back(worker, w);
    } catch (...) {
    }
    worker(0);
    for (auto& t : pool) t.join();
    for (auto& e : errors)
        if (e) std::rethrow_exception(e);
}

}  // namespace modaluq::detail
