// Bindings of layout.hpp and covariance.hpp. Sample matrices arrive as (channels x samples)
// column-major Refs: the Python layer passes y.T of a C-contiguous (n_samples, channels) array,
// which is that memory with no copy (noconvert() turns an accidental copy into an error).
#include <pybind11/eigen.h>
#include <pybind11/pybind11.h>
#include <pybind11/stl.h>

#include <modaluq/covariance.hpp>

#include <atomic>
#include <memory>
#include <stdexcept>

#include "bindings.hpp"

namespace py = pybind11;
using modaluq::Index;
using ConstRef = Eigen::Ref<const Eigen::MatrixXd>;

namespace {
// push/merge/finish release the GIL, and the C++ accumulator (like a std container) is not
// meant for concurrent use: two Python threads on one accumulator would corrupt it. The binding
// refuses the overlap with an error instead of serialising it, because two threads pushing to
// one stream interleave its samples in an order nobody chose.
struct GuardedAccumulator {
    modaluq::CovarianceAccumulator acc;
    std::atomic<bool> busy{false};

    /// Marks the accumulator in use for one call (compare_exchange cannot fail spuriously).
    struct Use {
        GuardedAccumulator& g;
        explicit Use(GuardedAccumulator& guarded) : g(guarded) {
            bool expected = false;
            if (!g.busy.compare_exchange_strong(expected, true))
                throw std::runtime_error(
                    "CovarianceAccumulator is in use by another thread: push, merge and finish must not overlap "
                    "(use one accumulator per thread and merge them in order, or guard it with a lock)");
        }
        ~Use() { g.busy.store(false); }
        Use(const Use&) = delete;
        Use& operator=(const Use&) = delete;
    };
};
}  // namespace

void modaluq::python::bind_covariance(py::module_& m) {
    py::class_<HankelLayout>(m, "HankelLayout")
        .def(py::init<>())
        .def_readwrite("n_outputs", &HankelLayout::n_outputs)
        .def_readwrite("n_inputs", &HankelLayout::n_inputs)
        .def_readwrite("block_rows", &HankelLayout::block_rows)
        .def_readwrite("past_block_rows", &HankelLayout::past_block_rows)
        .def_readwrite("references", &HankelLayout::references)
        .def_property_readonly("max_order", &HankelLayout::max_order)
        .def_property_readonly("window", &HankelLayout::window)
        .def("validate", &HankelLayout::validate);

    py::class_<Covariances>(m, "Covariances")
        .def_readonly("layout", &Covariances::layout)
        .def_readonly("n_samples", &Covariances::n_samples)
        .def_readonly("n_columns", &Covariances::n_columns)
        .def_readonly("block_length", &Covariances::block_length)
        .def_readonly("n_blocks", &Covariances::n_blocks)
        .def_readonly("channel_mean", &Covariances::channel_mean)
        .def_readonly("R1", &Covariances::R1)
        .def_readonly("R2", &Covariances::R2)
        .def_readonly("R3", &Covariances::R3)
        .def_readonly("R4", &Covariances::R4)
        .def_readonly("blocks", &Covariances::blocks)
        .def("covariance_factor",
             static_cast<Eigen::MatrixXd (Covariances::*)() const&>(&Covariances::covariance_factor));

    using State = CovarianceAccumulatorState;
    py::class_<State>(m, "CovarianceAccumulatorState")
        .def(py::init<>())
        .def_readwrite("layout", &State::layout)
        .def_readwrite("block_length", &State::block_length)
        .def_readwrite("demean", &State::demean)
        .def_readwrite("first_sample", &State::first_sample)
        .def_readwrite("end_sample", &State::end_sample)
        .def_readwrite("shift", &State::shift)
        .def_readwrite("total_sum", &State::total_sum)
        .def_readwrite("head", &State::head)
        .def_readwrite("tail", &State::tail)
        .def_readwrite("block_index", &State::block_index)
        .def_readwrite("block_count", &State::block_count)
        .def_readwrite("block_sums", &State::block_sums)
        .def_readwrite("window_start", &State::window_start)
        .def_readwrite("window_samples", &State::window_samples);

    using G = GuardedAccumulator;
    // A copy of the state under the guard (a push in another thread must not run during it).
    const auto copy_of = [](G& g) {
        G::Use use(g);
        return std::unique_ptr<G>(new G{g.acc});
    };
    py::class_<G>(m, "CovarianceAccumulator")
        .def_property_readonly_static("max_sample_magnitude",
                                      [](const py::object&) { return CovarianceAccumulator::kMaxSampleMagnitude; })
        .def(py::init([](HankelLayout layout, Index block_length, bool demean, Index first_sample) {
                 return new G{CovarianceAccumulator(std::move(layout), block_length, demean, first_sample)};
             }),
             py::arg("layout"), py::arg("block_length"), py::arg("demean") = true, py::arg("first_sample") = 0)
        .def_property_readonly("layout", [](const G& g) { return g.acc.layout(); })
        .def_property_readonly("block_length", [](const G& g) { return g.acc.block_length(); })
        .def_property_readonly("first_sample", [](const G& g) { return g.acc.first_sample(); })
        // end_sample and n_samples change while a push runs (GIL released): read under the guard.
        .def_property_readonly("end_sample", [](G& g) {
            G::Use use(g);
            return g.acc.end_sample();
        })
        .def_property_readonly("n_samples", [](G& g) {
            G::Use use(g);
            return g.acc.n_samples();
        })
        .def_property_readonly("demean", [](const G& g) { return g.acc.demean(); })
        .def_property_readonly("state_bytes", [](G& g) {
            G::Use use(g);
            return g.acc.state_bytes();
        })
        .def(
            "push",
            [](G& g, const ConstRef& y_t, const ConstRef& u_t) {
                G::Use use(g);
                g.acc.push(y_t, u_t);
            },
            py::arg("y_t").noconvert(), py::arg("u_t").noconvert(), py::call_guard<py::gil_scoped_release>())
        .def(
            "merge",
            [](G& g, G& next) {
                G::Use use(g);
                if (&next == &g) throw modaluq::invalid_argument("merge: an accumulator cannot be merged into itself");
                G::Use use_next(next);
                g.acc.merge(next.acc);
            },
            py::arg("next"), py::call_guard<py::gil_scoped_release>())
        .def(
            "finish",
            [](G& g, bool with_blocks) {
                G::Use use(g);
                return g.acc.finish(with_blocks);
            },
            py::arg("with_blocks") = true, py::call_guard<py::gil_scoped_release>())
        .def("export_state",
             [](G& g) {
                 G::Use use(g);
                 return g.acc.export_state();
             })
        .def_static(
            "from_state",
            [](const State& state) { return std::unique_ptr<G>(new G{CovarianceAccumulator::from_state(state)}); },
            py::arg("state"))
        .def("__copy__", copy_of)
        .def("__deepcopy__", [copy_of](G& g, const py::dict&) { return copy_of(g); }, py::arg("memo"));

    m.def("compute_covariances", &compute_covariances, py::arg("y_t").noconvert(), py::arg("u_t").noconvert(),
          py::arg("layout"), py::arg("n_blocks"), py::arg("demean") = true, py::arg("with_blocks") = true,
          py::arg("threads") = 1, py::call_guard<py::gil_scoped_release>());
}
