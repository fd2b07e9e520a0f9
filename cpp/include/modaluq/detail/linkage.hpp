#pragma once
/// @file detail/linkage.hpp
/// Agglomerative hierarchical clustering cut at a height (what scipy's linkage + fcluster with
/// criterion "distance" give), by the nearest-neighbour chain: O(n^2) time on a dense matrix.

#include <Eigen/Core>

#include <algorithm>
#include <limits>
#include <numeric>
#include <vector>

namespace modaluq {

/// How the distance between two clusters follows from their members' distances (Lance-Williams).
enum class Linkage {
    single,    ///< nearest members
    complete,  ///< farthest members
    average,   ///< mean over all pairs (UPGMA)
    weighted,  ///< mean of the two merged clusters' distances (WPGMA)
};

namespace detail {

/// Labels 0..k-1 (numbered by first point) of the flat clusters of `dist` (symmetric n x n,
/// zero diagonal): two points share a label when the dendrogram joins them at a height
/// <= threshold. All four linkages are reducible, so the nearest-neighbour chain builds the
/// same dendrogram as the naive algorithm (Muellner 2011, arXiv:1109.2378) and the heights are
/// monotone, which makes the cut the union of the merges at heights <= threshold.
inline std::vector<Eigen::Index> flat_clusters(Eigen::MatrixXd dist, Linkage linkage, double threshold) {
    using Index = Eigen::Index;
    const Index n = dist.rows();
    std::vector<Index> parent(n), size(n, 1), chain;
    std::iota(parent.begin(), parent.end(), Index(0));
    std::vector<char> active(n, 1);
    auto root = [&](Index i) {
        while (parent[i] != i) i = parent[i] = parent[parent[i]];
        return i;
    };
    // Slot s always holds the cluster containing point s (the merged cluster goes to the lower
    // slot), so a merge of slots a, b joins points a and b.
    for (Index remaining = n; remaining > 1;) {
        if (chain.empty())
            for (Index i = 0; i < n; ++i)
                if (active[i]) { chain.push_back(i); break; }
        const Index a = chain.back();
        const Index prev = chain.size() >= 2 ? chain[chain.size() - 2] : -1;
        Index c = prev;  // ties go to the previous link, which guarantees progress
        double best = prev >= 0 ? dist(a, prev) : std::numeric_limits<double>::infinity();
        for (Index x = 0; x < n; ++x)
            if (active[x] && x != a && (dist(a, x) < best || c < 0)) { best = dist(a, x); c = x; }
        if (c != prev) { chain.push_back(c); continue; }
        chain.pop_back();
        chain.pop_back();
        const Index s = std::min(a, c), t = std::max(a, c);
        const double ns = double(size[s]), nt = double(size[t]);
        for (Index k = 0; k < n; ++k) {
            if (!active[k] || k == s || k == t) continue;
            const double ds = dist(s, k), dt = dist(t, k);
            double d = 0.0;
            switch (linkage) {
                case Linkage::single: d = std::min(ds, dt); break;
                case Linkage::complete: d = std::max(ds, dt); break;
                case Linkage::average: d = (ns * ds + nt * dt) / (ns + nt); break;
                case Linkage::weighted: d = 0.5 * (ds + dt); break;
            }
            dist(s, k) = dist(k, s) = d;
        }
        active[t] = 0;
        size[s] += size[t];
        --remaining;
        if (best <= threshold) parent[root(t)] = root(s);
    }
    std::vector<Index> label(n, -1), label_of_root(n, -1);
    Index next = 0;
    for (Index i = 0; i < n; ++i) {
        const Index r = root(i);
        if (label_of_root[r] < 0) label_of_root[r] = next++;
        label[i] = label_of_root[r];
    }
    return label;
}

}  // namespace detail
}  // namespace modaluq
