#pragma once
// Declarations shared by the binding translation units (one per concept).
#include <pybind11/pybind11.h>

namespace modaluq::python {
void bind_covariance(pybind11::module_& m);
void bind_identify(pybind11::module_& m);
void bind_stabilization(pybind11::module_& m);
void bind_indicators(pybind11::module_& m);
void bind_interval(pybind11::module_& m);
void bind_multisetup(pybind11::module_& m);
void bind_poser(pybind11::module_& m);
}  // namespace modaluq::python
