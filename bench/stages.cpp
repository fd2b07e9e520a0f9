// Time per stage of the C++ core on the benchmark configurations (no Python).
// Build (bench/CMakeLists.txt): cmake -S . -B build/bench -DMODALUQ_BUILD_BENCH=ON -DMODALUQ_NATIVE=ON
//        && cmake --build build/bench --target stages; run build/bench/bench/stages [U3] with
//        OPENBLAS_NUM_THREADS=1 (large products through OpenBLAS when found)
#include <modaluq/modaluq.hpp>

#include <ctime>
#include <cstdio>
#include <random>
#include <string>

using namespace modaluq;
// CPU time of the process (one thread throughout: threads = 1, OPENBLAS_NUM_THREADS=1), so a busy
// machine does not inflate the stages as wall time would.
struct clk {
    using time_point = double;
    static double now() {
        timespec ts;
        clock_gettime(CLOCK_PROCESS_CPUTIME_ID, &ts);
        return double(ts.tv_sec) + 1e-9 * double(ts.tv_nsec);
    }
};
static double since(clk::time_point t) { return clk::now() - t; }

// AR(2) oscillators mixed into l channels: enough structure for the timing, no simulator needed.
static Eigen::MatrixXd signal(Index l, Index n, unsigned seed) {
    std::mt19937_64 g(seed);
    std::normal_distribution<double> nd;
    Eigen::MatrixXd y(l, n);
    const int k = 8;
    std::vector<double> a1(k), a2(k), x1(k, 0), x2(k, 0);
    for (int i = 0; i < k; ++i) {
        const double r = 0.995, th = 0.1 + 0.35 * i;
        a1[i] = 2 * r * std::cos(th);
        a2[i] = -r * r;
    }
    Eigen::MatrixXd mix = Eigen::MatrixXd::Random(l, k);
    Eigen::VectorXd s(k);
    for (Index t = 0; t < n; ++t) {
        for (int i = 0; i < k; ++i) {
            const double x = a1[i] * x1[i] + a2[i] * x2[i] + nd(g);
            x2[i] = x1[i];
            x1[i] = x;
            s(i) = x;
        }
        y.col(t) = mix * s;
        for (Index c = 0; c < l; ++c) y(c, t) += 0.1 * nd(g);
    }
    return y;
}

static void run(const char* name, Index l, Index n, Index p, Index nmax, Index nb, bool unc, Index n_refs = 0) {
    const Eigen::MatrixXd y = signal(l, n, 1);
    IdentifyOptions o;
    for (Index j = 0; j < n_refs; ++j) o.references.push_back(j * (l - 1) / std::max<Index>(1, n_refs - 1));
    o.fs = 50;
    o.block_rows = p;
    for (Index k = 2; k <= nmax; k += 2) o.orders.push_back(k);
    o.n_blocks = nb;
    o.uncertainty = unc;
    const HankelLayout L = o.layout(l, 0);
    auto t0 = clk::now();
    const Covariances cov = compute_covariances(y, Eigen::MatrixXd(), L, unc ? nb : 1, true, unc);
    const double t_cov = since(t0);
    t0 = clk::now();
    const SubspaceMatrix sub = subspace_matrix(cov);
    const Realization re(sub.H, l, nmax);
    const double t_svd = since(t0);
    double t_th = 0, t_prop = 0, t_orders = 0, t_floor = 0;
    Index k_star = 0, evaluated = 0;
    std::unique_ptr<UncertaintyPropagator> prop;
    if (unc) {
        t0 = clk::now();
        const Eigen::MatrixXd th = propagate_to_subspace(sub, cov, cov.covariance_factor());
        t_th = since(t0);
        t0 = clk::now();
        const detail::NoiseFloor nf = detail::noise_floor(re, th, L.rows_past(), 1.5, nmax + 1);
        t_floor = since(t0);
        k_star = nf.k;
        evaluated = (nf.delta.array() == nf.delta.array()).count();
        t0 = clk::now();
        prop = std::make_unique<UncertaintyPropagator>(re, th, L.rows_past());
        t_prop = since(t0) - t_floor;  // the propagator computes the floor again
    }
    t0 = clk::now();
    o.threads = 1;
    double t_eig = 0;
    for (Index k : o.orders) {
        const auto te = clk::now();
        const StateSpace ss = re.system(k);
        Eigenstructure eig;
        Modes m = modes_from_system(ss, o.fs, prop ? &eig : nullptr);
        t_eig += since(te);
        if (prop) prop->apply(m, eig, ss, o.fs, 100.0);
    }
    t_orders = since(t0);
    t0 = clk::now();
    identify(y, Eigen::MatrixXd(), o);
    const double t_all = since(t0);
    std::printf("%-3s cov %.3f  svd %.3f  T_H %.3f  noise floor %.3f (k* %ld, %ld delta_k)  dGamma+Q %.3f  "
                "orders %.3f (eig %.3f) | identify() %.3f s\n",
                name, t_cov, t_svd, t_th, t_floor, static_cast<long>(k_star), static_cast<long>(evaluated), t_prop,
                t_orders, t_eig, t_all);
}

// Usage: stages [U3|W1]   (U3 adds ~15 s and ~1 GB; W1, the wide array of bench/wide.py: 100
// channels, 8 references, 360,000 samples, p = q = 40, orders to 200, ~20 s and ~1 GB)
int main(int argc, char** argv) {
    run("S1", 3, 1000000, 40, 100, 50, false);
    run("U1", 3, 100000, 40, 100, 50, true);
    run("U2", 20, 100000, 20, 100, 50, true);
    if (argc > 1 && std::string(argv[1]) == "U3") run("U3", 20, 1000000, 40, 200, 100, true);
    if (argc > 1 && std::string(argv[1]) == "W1") run("W1", 100, 360000, 40, 200, 50, true, 8);
}
