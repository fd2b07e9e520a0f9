"""The reference paper's Monte Carlo results, copied from its Tables 1 and 2.

Source: P. Mellinger, M. Döhler, L. Mevel, "Variance estimation of modal parameters from
input/output covariance-driven subspace identification", ISMA 2016, Leuven (hal-01367695),
§5.1 "Simulation study": 10,000 records of N = 10,000 samples of the 6-DOF chain, model
order 12, output-only (OO) and input/output (IO).

Units are the paper's, and are written into every name:

* frequencies in Hz, their standard deviations in 10⁻² Hz (Table 2, "Hz · 10⁻²");
* damping ratios and their standard deviations in **per mille** (10⁻³).  The paper's column
  headers say "Damping ratio (%)", but the true damping ratio of 2 % is printed as "20.0",
  so the unit actually printed is ‰ (see docs/uq-math.md §11.4).  Table 2's σ_ξ values are
  read in the same unit; the IO values (0.3–0.5 ‰) agree with our own σ_ξ in that unit and
  would be 10 times too large read as %.

Table 2 prints the estimated standard deviation as "mean ± one-sigma sample spread of the
estimates over the records"; both numbers are kept.  Nothing here is computed: the numbers
are the ones printed in the paper, to the digits printed.
"""

from __future__ import annotations

__all__ = [
    "METHODS",
    "METHOD_LABELS",
    "PAPER_N_RECORDS",
    "PAPER_N_SAMPLES",
    "PAPER_ORDER",
    "PAPER_TABLE_1",
    "PAPER_TABLE_2",
]

#: The paper's two identifications, run on every record, in the order of the first array axis
#: of the Monte Carlo results.
METHODS = ("output-only", "input/output")
#: Short labels of :data:`METHODS` (the paper's "OO" and "IO").
METHOD_LABELS = {"output-only": "OO", "input/output": "IO"}

#: Number of Monte Carlo records in the paper (§5.1).
PAPER_N_RECORDS = 10_000
#: Samples per record in the paper (§5.1, tau = 0.02 s).
PAPER_N_SAMPLES = 10_000
#: Model order used in the paper's simulation study (six modes).
PAPER_ORDER = 12

#: Paper Table 1: "Means for frequencies and damping ratios from modal identification in
#: 10,000 Monte Carlo simulations".  Rows "Actual model", "OO", "IO"; frequencies in Hz,
#: damping ratios in per mille (printed "20.0" for 2 %), modes 1-6.
PAPER_TABLE_1 = {
    "actual": {
        "frequency_hz": (1.930, 5.618, 8.682, 14.49, 15.85, 17.01),
        "damping_permille": (20.0, 20.0, 20.0, 20.0, 20.0, 20.0),
    },
    "output-only": {
        "frequency_hz": (1.937, 5.618, 8.683, 14.49, 15.85, 17.01),
        "damping_permille": (29.4, 20.1, 20.1, 20.0, 20.0, 20.0),
    },
    "input/output": {
        "frequency_hz": (1.930, 5.618, 8.682, 14.49, 15.85, 17.01),
        "damping_permille": (20.2, 20.0, 20.0, 20.0, 20.0, 20.0),
    },
}

#: Paper Table 2: "Mean of estimated standard deviations (σ̄_est) and sample standard
#: deviations (σ_MC) for frequencies and damping ratios of the six modes in 10,000 Monte Carlo
#: simulations".  ``*_est`` is σ̄_est, ``*_est_spread`` the "±" printed after it (one-sigma
#: spread of the estimated std over the records), ``*_mc`` is σ_MC.  Frequency std in
#: 10⁻² Hz, damping-ratio std in per mille; modes 1-6.
PAPER_TABLE_2 = {
    "output-only": {
        "frequency_std_est_centihz": (2.02, 1.10, 1.55, 2.60, 2.64, 3.51),
        "frequency_std_est_spread_centihz": (1.80, 0.15, 0.21, 0.36, 0.38, 0.48),
        "frequency_std_mc_centihz": (1.99, 1.14, 1.59, 2.63, 2.65, 3.48),
        "damping_std_est_permille": (16.46, 1.98, 1.80, 1.70, 1.67, 2.09),
        "damping_std_est_spread_permille": (26.64, 0.28, 0.25, 0.22, 0.23, 0.28),
        "damping_std_mc_permille": (17.12, 2.07, 1.85, 1.71, 1.71, 2.09),
    },
    "input/output": {
        "frequency_std_est_centihz": (0.42, 0.24, 0.29, 0.66, 0.49, 0.87),
        "frequency_std_est_spread_centihz": (0.06, 0.03, 0.03, 0.08, 0.05, 0.10),
        "frequency_std_mc_centihz": (0.41, 0.25, 0.29, 0.68, 0.50, 0.87),
        "damping_std_est_permille": (2.13, 0.43, 0.33, 0.45, 0.31, 0.52),
        "damping_std_est_spread_permille": (0.34, 0.05, 0.04, 0.05, 0.04, 0.06),
        "damping_std_mc_permille": (2.07, 0.44, 0.34, 0.45, 0.31, 0.53),
    },
}
