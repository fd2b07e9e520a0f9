// Bindings of layout.hpp and covariance.hpp. Sample matrices arrive as (channels x samples)
// column-major Refs: the Python layer passes y.T of a C-contiguous (n_samples, channels) array,
// which is that memory with no copy (noconvert() turns an accidental copy into an error).
#include <pybind11/eigen.h>
#include <pybind11/pybind11.h>
#include <pybind11/stl.h>

#include <modaluq/covariance.hpp>

#include "bindings.hpp"

namespace py = pybind11;
using modaluq::Index;
using ConstRef = Eigen::Ref<const Eigen::MatrixXd>;

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

    py::class_<CovarianceAccumulator>(m, "CovarianceAccumulator")
        .def(py::init<HankelLayout, Index, bool, Index>(), py::arg("layout"), py::arg("block_length"),
             py::arg("demean") = true, py::arg("first_sample") = 0)
        .def_property_readonly("layout", &CovarianceAccumulator::layout)
        .def_property_readonly("block_length", &CovarianceAccumulator::block_length)
        .def_property_readonly("first_sample", &CovarianceAccumulator::first_sample)
        .def_property_readonly("end_sample", &CovarianceAccumulator::end_sample)
        .def_property_readonly("n_samples", &CovarianceAccumulator::n_samples)
        .def_property_readonly("demean", &CovarianceAccumulator::demean)
        .def("push", &CovarianceAccumulator::push, py::arg("y_t").noconvert(), py::arg("u_t").noconvert(),
             py::call_guard<py::gil_scoped_release>())
        .def("merge", &CovarianceAccumulator::merge, py::arg("next"), py::call_guard<py::gil_scoped_release>())
        .def("finish", &CovarianceAccumulator::finish, py::arg("with_blocks") = true,
             py::call_guard<py::gil_scoped_release>());

    m.def("compute_covariances", &compute_covariances, py::arg("y_t").noconvert(), py::arg("u_t").noconvert(),
          py::arg("layout"), py::arg("n_blocks"), py::arg("demean") = true, py::arg("with_blocks") = true,
          py::arg("threads") = 1, py::call_guard<py::gil_scoped_release>());
}
