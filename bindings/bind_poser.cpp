// Bindings of poser.hpp.
#include <pybind11/eigen.h>
#include <pybind11/pybind11.h>
#include <pybind11/stl.h>

#include <modaluq/poser.hpp>

#include <utility>
#include <vector>

#include "bindings.hpp"

namespace py = pybind11;

void modaluq::python::bind_poser(py::module_& m) {
    py::class_<PoserSetupModes>(m, "PoserSetupModes")
        .def(py::init([](Eigen::VectorXd frequency_hz, Eigen::VectorXd damping_ratio, Eigen::MatrixXcd mode_shape,
                         Eigen::MatrixXd covariance, std::vector<Index> references) {
                 PoserSetupModes s;
                 s.frequency_hz = std::move(frequency_hz);
                 s.damping_ratio = std::move(damping_ratio);
                 s.mode_shape = std::move(mode_shape);
                 s.covariance = std::move(covariance);
                 s.references = std::move(references);
                 return s;
             }),
             py::arg("frequency_hz"), py::arg("damping_ratio"), py::arg("mode_shape"), py::arg("covariance"),
             py::arg("references"))
        .def_readonly("frequency_hz", &PoserSetupModes::frequency_hz)
        .def_readonly("damping_ratio", &PoserSetupModes::damping_ratio)
        .def_readonly("mode_shape", &PoserSetupModes::mode_shape)
        .def_readonly("covariance", &PoserSetupModes::covariance)
        .def_readonly("references", &PoserSetupModes::references);

    py::class_<PoserOptions>(m, "PoserOptions")
        .def(py::init<>())
        .def_readwrite("frequency_tolerance", &PoserOptions::frequency_tolerance)
        .def_readwrite("min_reference_mac", &PoserOptions::min_reference_mac)
        .def_readwrite("min_setups", &PoserOptions::min_setups)
        .def_readwrite("reference_test_level", &PoserOptions::reference_test_level)
        .def("validate", &PoserOptions::validate);

    py::class_<PoserResult>(m, "PoserResult")
        .def_readonly("frequency_hz", &PoserResult::frequency_hz)
        .def_readonly("damping_ratio", &PoserResult::damping_ratio)
        .def_readonly("mode_shape", &PoserResult::mode_shape)
        .def_readonly("reference_component", &PoserResult::reference_component)
        .def_readonly("frequency_std", &PoserResult::frequency_std)
        .def_readonly("damping_std", &PoserResult::damping_std)
        .def_readonly("mode_shape_std_real", &PoserResult::mode_shape_std_real)
        .def_readonly("mode_shape_std_imag", &PoserResult::mode_shape_std_imag)
        .def_readonly("covariance", &PoserResult::covariance)
        .def_readonly("dof_setup", &PoserResult::dof_setup)
        .def_readonly("dof_channel", &PoserResult::dof_channel)
        .def_readonly("mode_index", &PoserResult::mode_index)
        .def_readonly("basis_setup", &PoserResult::basis_setup)
        .def_readonly("scale", &PoserResult::scale)
        .def_readonly("reference_dof", &PoserResult::reference_dof)
        .def_readonly("reference_chi2", &PoserResult::reference_chi2)
        .def_readonly("reference_p_value", &PoserResult::reference_p_value)
        .def_readonly("reference_z", &PoserResult::reference_z)
        .def_readonly("reference_rejected", &PoserResult::reference_rejected)
        .def_readonly("n_reference_tests", &PoserResult::n_reference_tests)
        .def_readonly("has_uncertainty", &PoserResult::has_uncertainty);

    m.def("poser_merge", &poser_merge, py::arg("setups"), py::arg("options") = PoserOptions{},
          py::call_guard<py::gil_scoped_release>());
}
