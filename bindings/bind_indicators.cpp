// Bindings of indicators.hpp: MPC, MPD and MAC with their std.
#include <pybind11/eigen.h>
#include <pybind11/pybind11.h>

#include <modaluq/indicators.hpp>

#include "bindings.hpp"

namespace py = pybind11;
using namespace modaluq;

void modaluq::python::bind_indicators(py::module_& m) {
    py::class_<IndicatorStatistics>(m, "IndicatorStatistics")
        .def_readonly("value", &IndicatorStatistics::value)
        .def_readonly("std", &IndicatorStatistics::std)
        .def_readonly("loss_at_maximum_mean", &IndicatorStatistics::loss_at_maximum_mean)
        .def_readonly("loss_at_maximum_std", &IndicatorStatistics::loss_at_maximum_std);
    m.def("modal_phase_collinearity", py::overload_cast<const Eigen::VectorXcd&>(&modal_phase_collinearity),
          py::arg("shape"));
    m.def("modal_phase_collinearity_statistics", &modal_phase_collinearity_statistics, py::arg("shape"),
          py::arg("cov"));
    m.def("mean_phase_deviation", &mean_phase_deviation, py::arg("shape"), py::arg("cov") = Eigen::MatrixXd());
    m.def("modal_assurance", &modal_assurance, py::arg("a"), py::arg("b"));
    using Independent = IndicatorStatistics (*)(const Eigen::VectorXcd&, const Eigen::MatrixXd&,
                                                const Eigen::VectorXcd&, const Eigen::MatrixXd&);
    using Joint = IndicatorStatistics (*)(const Eigen::VectorXcd&, const Eigen::VectorXcd&, const Eigen::MatrixXd&);
    m.def("modal_assurance_statistics", static_cast<Independent>(&modal_assurance_statistics), py::arg("a"),
          py::arg("cov_a"), py::arg("b"), py::arg("cov_b"));
    m.def("modal_assurance_statistics_joint", static_cast<Joint>(&modal_assurance_statistics), py::arg("a"),
          py::arg("b"), py::arg("joint"));
}
