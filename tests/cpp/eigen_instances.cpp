#define MODALUQ_TESTS_INSTANTIATE_EIGEN
#include "eigen_instances.hpp"
