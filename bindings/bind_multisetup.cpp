// Bindings of multisetup.hpp.
#include <pybind11/eigen.h>
#include <pybind11/pybind11.h>
#include <pybind11/stl.h>

#include <modaluq/multisetup.hpp>

#include <utility>
#include <vector>

#include "bindings.hpp"

namespace py = pybind11;

void modaluq::python::bind_multisetup(py::module_& m) {
    py::class_<SetupData>(m, "SetupData")
        .def(py::init([](Covariances covariances, std::vector<Index> references, double fs) {
                 SetupData s;
                 s.covariances = std::move(covariances);
                 s.references = std::move(references);
                 s.fs = fs;
                 return s;
             }),
             py::arg("covariances"), py::arg("references"), py::arg("fs") = 0.0)
        .def_readonly("covariances", &SetupData::covariances)
        .def_readonly("references", &SetupData::references)
        .def_readonly("fs", &SetupData::fs);

    // A SetupsIdentification is an Identification: everything that takes the core's
    // Identification (result_from_core, poles_of, stabilization_diagram) takes it.
    py::class_<SetupsIdentification, Identification>(m, "SetupsIdentification")
        .def_readonly("dof_setup", &SetupsIdentification::dof_setup)
        .def_readonly("dof_channel", &SetupsIdentification::dof_channel)
        .def_readonly("setup_singular_values", &SetupsIdentification::setup_singular_values)
        .def_readonly("setup_n_blocks", &SetupsIdentification::setup_n_blocks)
        .def_readonly("setup_signal_to_noise", &SetupsIdentification::setup_signal_to_noise)
        .def_readonly("setup_significant_singular_values", &SetupsIdentification::setup_significant_singular_values);

    m.def("identify_setups", &identify_setups, py::arg("setups"), py::arg("options"),
          py::call_guard<py::gil_scoped_release>());
}
