// Bindings of stabilization.hpp and selection.hpp.
#include <pybind11/eigen.h>
#include <pybind11/pybind11.h>
#include <pybind11/stl.h>

#include <modaluq/selection.hpp>
#include <modaluq/stabilization.hpp>

#include "bindings.hpp"

namespace py = pybind11;

void modaluq::python::bind_stabilization(py::module_& m) {
    py::enum_<PoleStatus>(m, "PoleStatus")
        .value("stable", PoleStatus::stable)
        .value("stable_frequency", PoleStatus::stable_frequency)
        .value("unstable", PoleStatus::unstable)
        .value("rejected", PoleStatus::rejected);
    py::enum_<Linkage>(m, "Linkage")
        .value("single", Linkage::single)
        .value("complete", Linkage::complete)
        .value("average", Linkage::average)
        .value("weighted", Linkage::weighted);
    py::enum_<ClusterStd>(m, "ClusterStd")
        .value("median", ClusterStd::median)
        .value("mean", ClusterStd::mean);
    py::enum_<Representative>(m, "Representative")
        .value("median", Representative::median)
        .value("lowest", Representative::lowest);
    py::enum_<DropReason>(m, "DropReason")
        .value("too_few_poles", DropReason::too_few_poles)
        .value("frequency_std_above_bandwidth", DropReason::frequency_std_above_bandwidth)
        .value("twin", DropReason::twin)
        .value("noise_twin", DropReason::noise_twin);

    py::class_<StabilityCriteria>(m, "StabilityCriteria")
        .def(py::init<>())
        .def_readwrite("max_frequency_change", &StabilityCriteria::max_frequency_change)
        .def_readwrite("max_damping_change", &StabilityCriteria::max_damping_change)
        .def_readwrite("min_mac", &StabilityCriteria::min_mac)
        .def_readwrite("frequency_std_factor", &StabilityCriteria::frequency_std_factor)
        .def_readwrite("max_frequency_cov", &StabilityCriteria::max_frequency_cov)
        .def_readwrite("min_damping_ratio", &StabilityCriteria::min_damping_ratio)
        .def_readwrite("max_damping_ratio", &StabilityCriteria::max_damping_ratio)
        .def_readwrite("damping_std_factor", &StabilityCriteria::damping_std_factor)
        .def_readwrite("max_damping_change_with_std", &StabilityCriteria::max_damping_change_with_std)
        .def_readwrite("match_window", &StabilityCriteria::match_window)
        .def_readwrite("frequency_range", &StabilityCriteria::frequency_range)
        .def_readwrite("min_mpc", &StabilityCriteria::min_mpc)
        .def_readwrite("max_mpd_deg", &StabilityCriteria::max_mpd_deg)
        .def("validate", &StabilityCriteria::validate);

    py::class_<Poles>(m, "Poles")
        .def(py::init<>())
        .def_readwrite("order", &Poles::order)
        .def_readwrite("frequency_hz", &Poles::frequency_hz)
        .def_readwrite("damping_ratio", &Poles::damping_ratio)
        .def_readwrite("frequency_std", &Poles::frequency_std)
        .def_readwrite("damping_std", &Poles::damping_std)
        .def_readwrite("mode_shape", &Poles::mode_shape)
        .def_readwrite("mode_shape_std_real", &Poles::mode_shape_std_real)
        .def_readwrite("mode_shape_std_imag", &Poles::mode_shape_std_imag)
        .def_readwrite("close_singular_values", &Poles::close_singular_values)
        .def_readwrite("noise_coupled", &Poles::noise_coupled)
        .def_readwrite("frequency_damping_correlation", &Poles::frequency_damping_correlation)
        .def_readwrite("block_too_short", &Poles::block_too_short)
        .def_readwrite("noise_coupling", &Poles::noise_coupling)
        .def_readwrite("frequency_damping_factor", &Poles::frequency_damping_factor)
        .def_readwrite("orders", &Poles::orders)
        .def_readwrite("noise_floor_order", &Poles::noise_floor_order)
        .def_readwrite("has_uncertainty", &Poles::has_uncertainty)
        .def("validate", &Poles::validate);
    m.def("poles_of", &poles_of, py::arg("identification"));

    py::class_<Diagram>(m, "Diagram")
        .def(py::init<>())
        .def_readwrite("poles", &Diagram::poles)
        .def_readwrite("status", &Diagram::status)
        .def_readwrite("reason", &Diagram::reason)
        .def_readwrite("matched_pole", &Diagram::matched_pole)
        .def_readwrite("frequency_change", &Diagram::frequency_change)
        .def_readwrite("damping_change", &Diagram::damping_change)
        .def_readwrite("mac", &Diagram::mac)
        .def_readwrite("frequency_change_std", &Diagram::frequency_change_std)
        .def_readwrite("mpc", &Diagram::mpc)
        .def_readwrite("mpd_deg", &Diagram::mpd_deg)
        .def_readwrite("criteria", &Diagram::criteria);
    m.def("stabilization_diagram", py::overload_cast<Poles, const StabilityCriteria&>(&stabilization_diagram),
          py::arg("poles"), py::arg("criteria"), py::call_guard<py::gil_scoped_release>());
    m.def("modal_assurance_criterion", &modal_assurance_criterion, py::arg("shape_a"), py::arg("shape_b"));

    py::class_<ClusteringOptions>(m, "ClusteringOptions")
        .def(py::init<>())
        .def_readwrite("distance_threshold", &ClusteringOptions::distance_threshold)
        .def_readwrite("min_cluster_size", &ClusteringOptions::min_cluster_size)
        .def_readwrite("min_cluster_fraction", &ClusteringOptions::min_cluster_fraction)
        .def_readwrite("per_cluster_min_size", &ClusteringOptions::per_cluster_min_size)
        .def_readwrite("max_frequency_std_per_bandwidth", &ClusteringOptions::max_frequency_std_per_bandwidth)
        .def_readwrite("merge_fragments", &ClusteringOptions::merge_fragments)
        .def_readwrite("drop_doublets", &ClusteringOptions::drop_doublets)
        .def_readwrite("doublet_window", &ClusteringOptions::doublet_window)
        .def_readwrite("doublet_min_mac", &ClusteringOptions::doublet_min_mac)
        .def_readwrite("fragment_std_factor", &ClusteringOptions::fragment_std_factor)
        .def_readwrite("fragment_min_mac", &ClusteringOptions::fragment_min_mac)
        .def_readwrite("fragment_max_shared", &ClusteringOptions::fragment_max_shared)
        .def_readwrite("statuses", &ClusteringOptions::statuses)
        .def_readwrite("linkage", &ClusteringOptions::linkage)
        .def_readwrite("cluster_std", &ClusteringOptions::cluster_std)
        .def_readwrite("representative", &ClusteringOptions::representative)
        .def_readwrite("shape_representative", &ClusteringOptions::shape_representative)
        .def_readwrite("order_discrepancy", &ClusteringOptions::order_discrepancy)
        .def_readwrite("drop_noise_twins", &ClusteringOptions::drop_noise_twins)
        .def_readwrite("reassign_borrowed_poles", &ClusteringOptions::reassign_borrowed_poles)
        .def_readwrite("unanchored_noise_coupling", &ClusteringOptions::unanchored_noise_coupling)
        .def("validate", &ClusteringOptions::validate);

    py::class_<SelectedModes>(m, "SelectedModes")
        .def_readonly("frequency_hz", &SelectedModes::frequency_hz)
        .def_readonly("damping_ratio", &SelectedModes::damping_ratio)
        .def_readonly("mode_shape", &SelectedModes::mode_shape)
        .def_readonly("frequency_std", &SelectedModes::frequency_std)
        .def_readonly("damping_std", &SelectedModes::damping_std)
        .def_readonly("mode_shape_std_real", &SelectedModes::mode_shape_std_real)
        .def_readonly("mode_shape_std_imag", &SelectedModes::mode_shape_std_imag)
        .def_readonly("frequency_spread", &SelectedModes::frequency_spread)
        .def_readonly("damping_spread", &SelectedModes::damping_spread)
        .def_readonly("mode_shape_spread_real", &SelectedModes::mode_shape_spread_real)
        .def_readonly("mode_shape_spread_imag", &SelectedModes::mode_shape_spread_imag)
        .def_readonly("min_mac", &SelectedModes::min_mac)
        .def_readonly("representative_order", &SelectedModes::representative_order)
        .def_readonly("representative_pole", &SelectedModes::representative_pole)
        .def_readonly("shape_pole", &SelectedModes::shape_pole)
        .def_readonly("shape_order", &SelectedModes::shape_order)
        .def_readonly("n_poles", &SelectedModes::n_poles)
        .def_readonly("order_min", &SelectedModes::order_min)
        .def_readonly("order_max", &SelectedModes::order_max)
        .def_readonly("members", &SelectedModes::members)
        .def_readonly("mode_of_pole", &SelectedModes::mode_of_pole)
        .def_readonly("dropped_frequency_hz", &SelectedModes::dropped_frequency_hz)
        .def_readonly("dropped_n_poles", &SelectedModes::dropped_n_poles)
        .def_readonly("dropped_reason", &SelectedModes::dropped_reason)
        .def_readonly("dropped_code", &SelectedModes::dropped_code)
        .def_readonly("dropped_min_size", &SelectedModes::dropped_min_size)
        .def_readonly("dropped_first_order", &SelectedModes::dropped_first_order)
        .def_readonly("dropped_frequency_std_per_bandwidth", &SelectedModes::dropped_frequency_std_per_bandwidth)
        .def_readonly("dropped_twin_mode", &SelectedModes::dropped_twin_mode)
        .def_readonly("dropped_twin_frequency_hz", &SelectedModes::dropped_twin_frequency_hz)
        .def_readonly("dropped_twin_mac", &SelectedModes::dropped_twin_mac)
        .def_readonly("frequency_std_per_bandwidth", &SelectedModes::frequency_std_per_bandwidth)
        .def_readonly("frequency_damping_correlation", &SelectedModes::frequency_damping_correlation)
        .def_readonly("block_too_short", &SelectedModes::block_too_short)
        .def_readonly("order_discrepancy", &SelectedModes::order_discrepancy)
        .def_readonly("unanchored", &SelectedModes::unanchored)
        .def_readonly("min_cluster_size", &SelectedModes::min_cluster_size)
        .def_readonly("max_frequency_std_per_bandwidth", &SelectedModes::max_frequency_std_per_bandwidth);
    m.def("select_modes", &select_modes, py::arg("diagram"), py::arg("options"),
          py::call_guard<py::gil_scoped_release>());
    // The core's clustering (detail/linkage.hpp) on its own: labels 0..k-1 numbered by first point.
    m.def(
        "cluster_labels",
        [](const Eigen::Ref<const Eigen::MatrixXd>& distances, Linkage linkage, double threshold) {
            detail::require(distances.rows() == distances.cols(), "distances must be a square matrix, got ",
                            distances.rows(), " x ", distances.cols());
            detail::require(!std::isnan(threshold), "threshold must be a number, got NaN");
            detail::require(distances.allFinite(), "distances must be finite");
            detail::require(distances == distances.transpose(), "distances must be symmetric");
            detail::require((distances.diagonal().array() == 0.0).all(), "distances must have a zero diagonal");
            std::vector<Index> labels = detail::flat_clusters(distances, linkage, threshold);
            return IndexVector(Eigen::Map<const IndexVector>(labels.data(), Index(labels.size())));
        },
        py::arg("distances"), py::arg("linkage"), py::arg("threshold"), py::call_guard<py::gil_scoped_release>());
}
