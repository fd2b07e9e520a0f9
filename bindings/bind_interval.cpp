// Bindings of interval.hpp: the Student-t probability and quantile and the interval factor.
#include <pybind11/pybind11.h>

#include <modaluq/interval.hpp>

#include "bindings.hpp"

namespace py = pybind11;

void modaluq::python::bind_interval(py::module_& m) {
    m.def("student_t_probability", &modaluq::student_t_probability, py::arg("t"), py::arg("dof"));
    m.def("student_t_quantile", &modaluq::student_t_quantile, py::arg("level"), py::arg("dof"));
    m.def("interval_factor", &modaluq::interval_factor, py::arg("n_blocks"), py::arg("level") = 0.95);
    m.attr("max_interval_level") = modaluq::max_interval_level;
}
