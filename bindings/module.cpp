// modaluq._core: thin translation of the C++ core. All logic lives in cpp/include/modaluq.
#include <pybind11/eigen.h>
#include <pybind11/pybind11.h>

#include <cstdint>

#include <modaluq/detail/gemm.hpp>
#include <modaluq/errors.hpp>
#include <modaluq/version.hpp>

#include "bindings.hpp"

namespace py = pybind11;

PYBIND11_MODULE(_core, m) {
    m.doc() = "modaluq C++ core (covariance-driven SSI with analytic uncertainty)";
    m.attr("__version__") = modaluq::version;
    // Whether the core's large products go to a BLAS in this build (detail/gemm.hpp).
    m.attr("uses_blas") = modaluq::detail::gemm_uses_blas();

    // invalid_argument derives from std::invalid_argument, which pybind11 maps to ValueError.
    static py::exception<modaluq::numerical_error> numerical(m, "NumericalError", PyExc_ArithmeticError);
    py::register_exception_translator([](std::exception_ptr p) {
        try {
            if (p) std::rethrow_exception(p);
        } catch (const modaluq::numerical_error& e) {
            py::set_error(numerical, e.what());
        }
    });

    // Address of the memory a C++ Ref sees: lets a test prove the binding did not copy y.
    m.def("_data_pointer",
          [](const Eigen::Ref<const Eigen::MatrixXd>& x) { return reinterpret_cast<std::uintptr_t>(x.data()); },
          py::arg("x").noconvert());

    modaluq::python::bind_covariance(m);
    modaluq::python::bind_identify(m);
    modaluq::python::bind_stabilization(m);
    modaluq::python::bind_indicators(m);
    modaluq::python::bind_multisetup(m);
}
