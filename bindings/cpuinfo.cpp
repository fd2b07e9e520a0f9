// modaluq._core_cpuinfo: the instruction sets this CPU runs and the OS enables, for
// python/modaluq/_dispatch.py to choose the core's path. A module of its own in the plain C API:
// asking must not load a core (pybind11 registers a core's C++ types once per process, so a
// second core would fail to load).
#define PY_SSIZE_T_CLEAN
#include <Python.h>

namespace {

bool put(PyObject* dict, const char* name, bool value) {
    return PyDict_SetItemString(dict, name, value ? Py_True : Py_False) == 0;
}

// {feature: bool} in libgcc's names; empty where the compiler cannot ask (not x86, not GCC/Clang).
// libgcc's answer includes the OS: AVX and the features built on it count only when XGETBV says
// the OS saves the AVX registers.
PyObject* features(PyObject*, PyObject*) {
    PyObject* d = PyDict_New();
    if (!d) return nullptr;
#if (defined(__x86_64__) || defined(__i386__)) && (defined(__GNUC__) || defined(__clang__))
    __builtin_cpu_init();
#define MODALUQ_FEATURE(name) \
    if (!put(d, name, __builtin_cpu_supports(name))) goto fail;
    MODALUQ_FEATURE("sse3")
    MODALUQ_FEATURE("ssse3")
    MODALUQ_FEATURE("sse4.1")
    MODALUQ_FEATURE("sse4.2")
    MODALUQ_FEATURE("popcnt")
    MODALUQ_FEATURE("avx")
    MODALUQ_FEATURE("avx2")
    MODALUQ_FEATURE("fma")
    MODALUQ_FEATURE("bmi")
    MODALUQ_FEATURE("bmi2")
    MODALUQ_FEATURE("f16c")
#if defined(__GNUC__) && !defined(__clang__) && __GNUC__ >= 12
    // libgcc 12 knows these names, and x86-64-v3 as a whole (all of the above, MOVBE, LZCNT, XSAVE)
    MODALUQ_FEATURE("movbe")
    MODALUQ_FEATURE("lzcnt")
    MODALUQ_FEATURE("x86-64-v3")
#endif
#undef MODALUQ_FEATURE
    return d;
fail:
    Py_DECREF(d);
    return nullptr;
#else
    return d;
#endif
}

PyMethodDef methods[] = {
    {"features", features, METH_NOARGS,
     "features() -> dict[str, bool]: the x86 instruction sets this CPU and OS support (__builtin_cpu_supports); "
     "empty where they cannot be asked"},
    {nullptr, nullptr, 0, nullptr}};

PyModuleDef module = {PyModuleDef_HEAD_INIT, "_core_cpuinfo", "Which instruction sets this CPU runs", -1, methods,
                      nullptr, nullptr, nullptr, nullptr};

}  // namespace

PyMODINIT_FUNC PyInit__core_cpuinfo() { return PyModule_Create(&module); }
