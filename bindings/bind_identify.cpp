// Bindings of modal.hpp and identify.hpp.
#include <pybind11/eigen.h>
#include <pybind11/pybind11.h>
#include <pybind11/stl.h>

#include <modaluq/identify.hpp>

#include "bindings.hpp"

namespace py = pybind11;
using ConstRef = Eigen::Ref<const Eigen::MatrixXd>;

void modaluq::python::bind_identify(py::module_& m) {
    py::class_<Modes>(m, "Modes")
        .def_readonly("order", &Modes::order)
        .def_readonly("eigenvalue", &Modes::eigenvalue)
        .def_readonly("frequency_hz", &Modes::frequency_hz)
        .def_readonly("damping_ratio", &Modes::damping_ratio)
        .def_readonly("mode_shape", &Modes::mode_shape)
        .def_readonly("reference_component", &Modes::reference_component)
        .def_readonly("frequency_std", &Modes::frequency_std)
        .def_readonly("damping_std", &Modes::damping_std)
        .def_readonly("mode_shape_std_real", &Modes::mode_shape_std_real)
        .def_readonly("mode_shape_std_imag", &Modes::mode_shape_std_imag)
        .def_readonly("covariance", &Modes::covariance)
        .def_readonly("frequency_damping_factor", &Modes::frequency_damping_factor)
        .def_readonly("mode_shape_factor", &Modes::mode_shape_factor)
        .def_readonly("frequency_damping_correlation", &Modes::frequency_damping_correlation)
        .def_readonly("block_too_short", &Modes::block_too_short)
        .def_readonly("singular_value_gap", &Modes::singular_value_gap)
        .def_readonly("close_singular_values", &Modes::close_singular_values)
        .def_readonly("noise_coupling", &Modes::noise_coupling)
        .def_readonly("noise_coupled", &Modes::noise_coupled)
        .def_readonly("block_correlation_scale", &Modes::block_correlation_scale)
        .def_readonly("bootstrapped", &Modes::bootstrapped)
        .def_readonly("degenerate", &Modes::degenerate)
        .def_readonly("note", &Modes::note);

    py::enum_<IdentificationWarning>(m, "IdentificationWarning")
        .value("input_rank_deficient", IdentificationWarning::input_rank_deficient)
        .value("too_few_blocks", IdentificationWarning::too_few_blocks)
        .value("low_signal_to_noise", IdentificationWarning::low_signal_to_noise)
        .value("degenerate_orders", IdentificationWarning::degenerate_orders)
        .value("slow_decay", IdentificationWarning::slow_decay);
    py::class_<SlowDecay>(m, "SlowDecay")
        .def(py::init<>())
        .def_readonly("n_poles", &SlowDecay::n_poles)
        .def_readonly("block_seconds", &SlowDecay::block_seconds)
        .def_readonly("longest_decay_s", &SlowDecay::longest_decay_s)
        .def_readonly("record_seconds", &SlowDecay::record_seconds)
        .def_readonly("fitting_n_blocks", &SlowDecay::fitting_n_blocks)
        .def_property_readonly("record_too_short", &SlowDecay::record_too_short);

    py::class_<IdentifyOptions>(m, "IdentifyOptions")
        .def(py::init<>())
        .def_readwrite("fs", &IdentifyOptions::fs)
        .def_readwrite("block_rows", &IdentifyOptions::block_rows)
        .def_readwrite("past_block_rows", &IdentifyOptions::past_block_rows)
        .def_readwrite("orders", &IdentifyOptions::orders)
        .def_readwrite("n_blocks", &IdentifyOptions::n_blocks)
        .def_readwrite("references", &IdentifyOptions::references)
        .def_readwrite("uncertainty", &IdentifyOptions::uncertainty)
        .def_readwrite("demean", &IdentifyOptions::demean)
        .def_readwrite("input_rcond", &IdentifyOptions::input_rcond)
        .def_readwrite("threads", &IdentifyOptions::threads)
        .def_readwrite("freeze_noise", &IdentifyOptions::freeze_noise)
        .def_readwrite("noise_floor_factor", &IdentifyOptions::noise_floor_factor)
        .def_readwrite("noise_coupling_limit", &IdentifyOptions::noise_coupling_limit)
        .def_readwrite("block_correlation_correction", &IdentifyOptions::block_correlation_correction)
        .def_readwrite("bootstrap_draws", &IdentifyOptions::bootstrap_draws)
        .def_readwrite("coupling_sketch", &IdentifyOptions::coupling_sketch)
        .def_readwrite("keep_shape_factor", &IdentifyOptions::keep_shape_factor)
        .def("validate", &IdentifyOptions::validate)
        .def_property_readonly_static("max_threads", [](py::object) { return IdentifyOptions::kMaxThreads; })
        .def_property_readonly_static("min_bootstrap_draws",
                                      [](py::object) { return IdentifyOptions::kMinBootstrapDraws; })
        .def("layout", &IdentifyOptions::layout, py::arg("n_outputs"), py::arg("n_inputs"));

    py::class_<Identification>(m, "Identification")
        .def_readonly("modes", &Identification::modes)
        .def_readonly("singular_values", &Identification::singular_values)
        .def_readonly("n_samples", &Identification::n_samples)
        .def_readonly("n_columns", &Identification::n_columns)
        .def_readonly("block_length", &Identification::block_length)
        .def_readonly("n_blocks", &Identification::n_blocks)
        .def_readonly("channel_mean", &Identification::channel_mean)
        .def_readonly("input_rank", &Identification::input_rank)
        .def_readonly("input_condition", &Identification::input_condition)
        .def_readonly("input_rank_deficient", &Identification::input_rank_deficient)
        .def_readonly("too_few_blocks", &Identification::too_few_blocks)
        .def_readonly("numerical_rank", &Identification::numerical_rank)
        .def_readonly("signal_to_noise", &Identification::signal_to_noise)
        .def_readonly("low_signal_to_noise", &Identification::low_signal_to_noise)
        .def_readonly("significant_singular_values", &Identification::significant_singular_values)
        .def_readonly("slow_decay", &Identification::slow_decay)
        .def_readonly("warnings", &Identification::warnings)
        .def_readonly("warning_codes", &Identification::warning_codes);

    m.def("identify", py::overload_cast<const ConstRef&, const ConstRef&, IdentifyOptions>(&identify),
          py::arg("y_t").noconvert(), py::arg("u_t").noconvert(), py::arg("options"),
          py::call_guard<py::gil_scoped_release>());
    m.def("identify_covariances", py::overload_cast<const Covariances&, IdentifyOptions>(&identify),
          py::arg("covariances"), py::arg("options"), py::call_guard<py::gil_scoped_release>());
}
