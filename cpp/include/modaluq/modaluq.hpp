#pragma once
/// @file modaluq.hpp
/// Umbrella header: covariance-driven SSI (output-only and input/output) with the analytic
/// uncertainty of every modal parameter at every model order.

#include "covariance.hpp"
#include "errors.hpp"
#include "identify.hpp"
#include "indicators.hpp"
#include "interval.hpp"
#include "layout.hpp"
#include "modal.hpp"
#include "multisetup.hpp"
#include "poser.hpp"
#include "realization.hpp"
#include "selection.hpp"
#include "stabilization.hpp"
#include "subspace.hpp"
#include "uncertainty.hpp"
#include "version.hpp"
