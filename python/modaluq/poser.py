"""PoSER for campaigns in several setups, and the reference-consistency check of both methods.

PoSER (docs/uq-math.md §13.5, §13.9): each setup is identified alone and its modes selected as
for one record (:func:`~modaluq.select_modes` on its own stabilization diagram); the core's
``poser_merge`` (``cpp/include/modaluq/poser.hpp``) matches the modes across setups, combines f
and ξ by inverse-variance weights, rescales each setup's shape onto the reference components of
the first setup that has the mode, and propagates each setup's covariance to the global f, ξ
and shape. The merge also tests, per setup and mode, whether the setup's reference components
agree with the basis setup's up to one complex scale within their covariance (a χ² with 2r − 2
degrees of freedom): a mislabelled or moved reference fails it, and
:class:`ReferenceMismatchWarning` names the setup, the channel, the mode and the statistic.
:func:`modaluq.identify_setups` runs the same check after the modular merge.
"""

from __future__ import annotations

import dataclasses
import warnings
from dataclasses import dataclass, field

import numpy as np

from . import _core
from ._blas import single_threaded as single_threaded_blas
from .indicators import mean_phase_deviation, modal_phase_collinearity, shape_covariance
from .results import ModalUQWarning, result_from_core
from .selection import SelectedModes, select_modes
from .stabilization import stabilization_diagram

#: Family-wise level of the reference test (the core's PoserOptions.reference_test_level, set
#: explicitly): strict, so that correct campaigns stay silent (docs/uq-math.md §13.9).
REFERENCE_TEST_LEVEL = 1e-6

__all__ = ["REFERENCE_TEST_LEVEL", "PoserResult", "ReferenceCheck", "ReferenceMismatchWarning", "identify_each_setup",
           "poser_merge", "reference_check", "reference_check_orders", "warn_reference_mismatch"]


class ReferenceMismatchWarning(ModalUQWarning):
    """A setup's reference components disagree with the basis setup's beyond their σ: a reference
    channel mislabelled, moved or with a wrong sign in that setup (or a mode matched wrongly)."""


@dataclass(frozen=True)
class ReferenceCheck:
    """Per setup and merged mode, the consistency of the setup's reference components with the
    basis setup's (docs/uq-math.md §13.9): the residual e = b − α ϕ of the complex least-squares
    scale, χ² = eᵀ Σ_e⁻¹ e on its 2r − 2 free directions, its p-value, and per reference channel
    z = |e_c| / σ(e_c). NaN where not tested (the basis setup, a setup without the mode, one
    reference only, no uncertainty). ``rejected``: p below ``level`` / ``n_tests`` (Bonferroni
    over the campaign's tests)."""

    frequency_hz: np.ndarray     #: (n_modes,) the merged modes' frequencies, Hz
    reference_names: tuple       #: the r reference channels
    dof: int                     #: 2r − 2
    chi2: np.ndarray             #: (n_setups, n_modes)
    p_value: np.ndarray          #: (n_setups, n_modes)
    z: np.ndarray                #: (n_setups, r, n_modes)
    rejected: np.ndarray         #: (n_setups, n_modes) bool
    basis_setup: np.ndarray      #: (n_modes,) the setup whose references are the basis
    n_tests: int
    level: float

    def suspects(self) -> dict:
        """{setup: [modes]}: the setups whose references the rejections point at. A rejection of
        setup j for mode m points at j, unless every setup tested for m disagrees with the basis
        (two or more): then the basis setup is the suspect."""
        out = {}
        for m in range(self.rejected.shape[1] if self.rejected.ndim == 2 else 0):
            tested = np.isfinite(self.chi2[:, m])
            bad = self.rejected[:, m]
            if bad.sum() >= 2 and bad.sum() == tested.sum():
                out.setdefault(int(self.basis_setup[m]), []).append(m)
            else:
                for j in np.flatnonzero(bad):
                    out.setdefault(int(j), []).append(m)
        return dict(sorted(out.items()))

    def messages(self) -> list:
        """One sentence per suspect setup (:meth:`suspects`), naming its reference channels, the
        modes and the statistic: what :func:`warn_reference_mismatch` issues."""
        out = []
        names = self.reference_names
        for j, modes in self.suspects().items():
            parts, zsum = [], np.zeros(len(names))
            for m in modes:
                k = j if np.isfinite(self.chi2[j, m]) else int(np.nanargmax(self.chi2[:, m]))  # basis: worst pair
                zsum += np.nan_to_num(self.z[k, :, m])
                zs = ", ".join(f"{n} z = {z:.1f}" for n, z in zip(names, self.z[k, :, m]))
                parts.append(f"{self.frequency_hz[m]:.4g} Hz: chi2 = {self.chi2[k, m]:.3g} ({self.dof} dof, "
                             f"p = {self.p_value[k, m]:.2g}; {zs})")
            basis = {int(self.basis_setup[m]) for m in modes}
            against = ("every other setup" if j in basis else
                       "setup " + ", ".join(str(b) for b in sorted(basis)))
            if len(names) == 2:
                which = f"reference {names[0]!r} or {names[1]!r} (two references cannot tell which)"
            else:
                c = int(np.argmax(zsum))
                which = f"reference {names[c]!r} (largest residual)"
            out.append(f"setup {j}: its reference channels disagree with {against}'s beyond their std in "
                       f"{len(modes)} mode(s) ({'; '.join(parts)}): {which} may be mislabelled, moved or of the "
                       f"wrong sign in setup {j} (level {self.level:g} over {self.n_tests} tests)")
        return out


@dataclass(frozen=True)
class PoserResult:
    """What ``identify_setups(..., method="poser")`` returns.

    :meth:`select_modes` gives the merged modes as a :class:`~modaluq.SelectedModes` over the
    global DOFs (``output_names``, the references once): the same type as the modular merge's,
    so tables, exports, ``plot_shape`` with a geometry and ``to_dataframe`` take it unchanged.
    Its ``*_std`` and ``mode_covariance`` are the propagated first-order ones; the fields that
    describe one cluster of one diagram (``*_spread``, ``members``, ``representative_*``,
    ``n_poles``) have no single value in a merge: they are those of the basis setup's cluster
    (``*_spread`` NaN, ``members`` empty).
    """

    setups: tuple                #: per setup, its own :class:`~modaluq.Result`
    output_names: tuple          #: the global DOFs: references, then each setup's other channels
    reference_names: tuple
    fs: float
    settings: dict
    merged: SelectedModes        #: the merged modes
    reference_check: ReferenceCheck
    #: (n_setups, n_modes) per setup, the index of its selected mode merged (-1: none)
    mode_index: np.ndarray
    scale: np.ndarray            #: (n_setups, n_modes) the complex scale α_j of each setup's shape
    setup_modes: tuple           #: per setup, the :class:`~modaluq.SelectedModes` merged
    warnings: tuple = field(default_factory=tuple)

    @property
    def n_outputs(self) -> int:
        return len(self.output_names)

    def select_modes(self) -> SelectedModes:
        """The merged modes with their σ (already selected: each setup's modes were selected on
        its own diagram)."""
        return self.merged

    def __str__(self) -> str:
        return (f"modaluq PoSER merge of {len(self.setups)} setups, {self.n_outputs} global DOFs\n"
                + str(self.merged) + "".join(f"\nwarning: {w}" for w in self.warnings))


def identify_each_setup(core_setups, options, record: dict, names_per_setup, n_inputs_per_setup) -> tuple:
    """Each setup identified alone from its covariances (the core's ``identify_covariances``), as
    :class:`~modaluq.Result` s with the setup's channel names."""
    out = []
    for j, (st, names, n_in) in enumerate(zip(core_setups, names_per_setup, n_inputs_per_setup)):
        with single_threaded_blas():
            ident = _core.identify_covariances(st.covariances, options)
        rec = dict(record, setup=j, setups=None)
        out.append(result_from_core(ident, rec, len(names), n_in, output_names=names))
    return tuple(out)


def _setup_modes(sel: SelectedModes, r: int):
    """The core's PoserSetupModes of one setup's selection (its references are its first r rows)."""
    cov = np.zeros((0, 0))
    if sel.mode_covariance is not None and sel.n_modes:
        cov = np.stack([c.reshape(-1, order="F") for c in sel.mode_covariance], axis=1)
    return _core.PoserSetupModes(np.asarray(sel.frequency_hz, float), np.asarray(sel.damping_ratio, float),
                                 np.asarray(sel.mode_shape, complex), cov, list(range(r)))


def poser_merge(setup_modes, reference_names, *, options=None):
    """The core's PoSER merge of each setup's :class:`~modaluq.SelectedModes` (references first in each)."""
    r = len(reference_names)
    with single_threaded_blas():
        return _core.poser_merge([_setup_modes(s, r) for s in setup_modes],
                                 _core.PoserOptions() if options is None else options)


def reference_check(merged, reference_names, level: float) -> ReferenceCheck:
    """The :class:`ReferenceCheck` of a core ``PoserResult``."""
    z = np.stack([np.asarray(z) for z in merged.reference_z]) if len(merged.reference_z) else np.zeros((0, 0, 0))
    return ReferenceCheck(
        frequency_hz=np.asarray(merged.frequency_hz), reference_names=tuple(reference_names),
        dof=int(merged.reference_dof), chi2=np.asarray(merged.reference_chi2),
        p_value=np.asarray(merged.reference_p_value), z=z, rejected=np.asarray(merged.reference_rejected, bool),
        basis_setup=np.asarray(merged.basis_setup, np.int64), n_tests=int(merged.n_reference_tests), level=level)


def warn_reference_mismatch(check: ReferenceCheck, stacklevel: int = 3) -> list:
    """Issue one :class:`ReferenceMismatchWarning` per rejected (setup, mode); returns the messages."""
    msgs = check.messages()
    for m in msgs:
        warnings.warn(m, ReferenceMismatchWarning, stacklevel=stacklevel)
    return msgs


def _global_selected(merged, setup_modes, dof_names) -> SelectedModes:
    """A :class:`SelectedModes` over the global DOFs from the core's PoserResult."""
    nm, l_g = len(merged.frequency_hz), len(dof_names)
    nan = np.full(nm, np.nan)
    idx = np.asarray(merged.mode_index)
    basis = np.asarray(merged.basis_setup, np.int64)
    bsel = [setup_modes[int(b)] for b in basis]
    bi = [int(idx[b, t]) for t, b in enumerate(basis)]
    has_unc = bool(merged.has_uncertainty)
    covs = None
    if has_unc and nm:
        n = 2 + 2 * l_g
        covs = np.stack([np.asarray(merged.covariance)[:, t].reshape(n, n, order="F") for t in range(nm)])

    def per_mode(name, dtype):
        return np.array([getattr(s, name)[i] for s, i in zip(bsel, bi)], dtype=dtype)

    def any_setup(name):  # a flag of a merged mode: set in any setup that has the mode
        return np.array([any(bool(getattr(s, name)[int(idx[j, t])]) for j, s in enumerate(setup_modes)
                             if idx[j, t] >= 0) for t in range(nm)], dtype=bool)

    sel = SelectedModes(
        frequency_hz=np.asarray(merged.frequency_hz), damping_ratio=np.asarray(merged.damping_ratio),
        mode_shape=np.asarray(merged.mode_shape),
        frequency_std=np.asarray(merged.frequency_std) if has_unc else nan.copy(),
        damping_std=np.asarray(merged.damping_std) if has_unc else nan.copy(),
        mode_shape_std_real=np.asarray(merged.mode_shape_std_real) if has_unc else np.full((l_g, nm), np.nan),
        mode_shape_std_imag=np.asarray(merged.mode_shape_std_imag) if has_unc else np.full((l_g, nm), np.nan),
        frequency_spread=nan.copy(), damping_spread=nan.copy(),
        mode_shape_spread_real=np.full((l_g, nm), np.nan), mode_shape_spread_imag=np.full((l_g, nm), np.nan),
        min_mac=nan.copy(), representative_order=per_mode("representative_order", np.int64),
        representative_pole=np.full(nm, -1, np.int64), n_poles=per_mode("n_poles", np.int64),
        # the basis setup's shape (its order) and the selection that read it; no pole of a merged diagram
        shape_order=per_mode("shape_order", np.int64), shape_pole=np.full(nm, -1, np.int64),
        settings=setup_modes[0].settings,
        order_min=per_mode("order_min", np.int64), order_max=per_mode("order_max", np.int64),
        members=tuple(np.zeros(0, np.int64) for _ in range(nm)), mode_of_pole=np.zeros(0, np.int64),
        dropped_frequency_hz=np.zeros(0), dropped_n_poles=np.zeros(0, np.int64), min_cluster_size=0,
        output_names=tuple(dof_names), has_uncertainty=has_unc,
        block_too_short=any_setup("block_too_short"), order_discrepancy=any_setup("order_discrepancy"),
        mode_covariance=covs,
        # the intervals' blocks: the fewest of a setup (each merged σ rests on every setup's; the
        # conservative count), unknown (0) where a setup's is
        n_blocks=min((int(s.n_blocks) for s in setup_modes), default=0) if has_unc else 0)
    mpc, mpd = [], []
    for k in range(nm):
        shape = sel.mode_shape[:, k]
        if not np.all(np.isfinite(shape)):  # DOFs of a setup without the mode
            mpc.append(None)
            mpd.append(None)
            continue
        shape_cov = None if covs is None else shape_covariance(covs[k])
        mpc.append(modal_phase_collinearity(shape, shape_cov))
        mpd.append(mean_phase_deviation(shape, shape_cov))

    def values(xs, attr):
        return np.array([np.nan if x is None else getattr(x, attr) for x in xs], float)

    ind = dict(mpc=values(mpc, "value"), mpc_std=values(mpc, "std"), mpd_deg=values(mpd, "value"),
               mpd_std_deg=values(mpd, "std"))
    return dataclasses.replace(sel, **ind)


def identify_poser(core_setups, options, record: dict, names_per_setup, n_inputs_per_setup, dof_names,
                   reference_names, *, criteria=None, clustering=None, poser_options=None) -> PoserResult:
    """PoSER on prepared setups (``identify_setups`` makes them): each identified alone, its modes
    selected, then merged (:func:`poser_merge`); a mislabelled reference is warned about."""
    results = identify_each_setup(core_setups, options, record, names_per_setup, n_inputs_per_setup)
    selected = tuple(select_modes(stabilization_diagram(res, criteria), clustering) for res in results)
    opts = poser_options
    if opts is None:
        opts = _core.PoserOptions()
        opts.reference_test_level = REFERENCE_TEST_LEVEL
    merged = poser_merge(selected, reference_names, options=opts)
    check = reference_check(merged, reference_names, opts.reference_test_level)
    msgs = warn_reference_mismatch(check, stacklevel=4)
    own = tuple(f"setup {j}: {w}" for j, res in enumerate(results) for w in res.warnings)
    for w in own:
        warnings.warn(w, ModalUQWarning, stacklevel=4)
    return PoserResult(
        setups=results, output_names=tuple(dof_names), reference_names=tuple(reference_names),
        fs=float(record["fs"]), settings=dict(record, method="poser"),
        merged=_global_selected(merged, selected, dof_names), reference_check=check,
        mode_index=np.asarray(merged.mode_index, np.int64), scale=np.asarray(merged.scale), setup_modes=selected,
        warnings=own + tuple(msgs))


#: The modular merge's reference check identifies each setup at most at this many of the orders.
REFERENCE_CHECK_ORDERS = 12


def reference_check_orders(orders, at_most: int = REFERENCE_CHECK_ORDERS) -> list:
    """At most ``at_most`` of ``orders``, evenly spread and the highest kept: the reference check
    needs each setup's modes with their σ, not a fine diagram, and each order of a setup's diagram
    costs about as much as its whole identification at the highest order divided by the number
    of orders (bench/multisetup.py)."""
    orders = sorted({int(n) for n in orders})
    if len(orders) <= at_most:
        return orders
    picks = np.unique(np.round(np.linspace(0, len(orders) - 1, at_most)).astype(int))
    return [orders[i] for i in picks]


def check_references_after_modular(core_setups, options, record: dict, names_per_setup, n_inputs_per_setup,
                                   reference_names) -> ReferenceCheck | None:
    """The reference check for the modular merge: each setup identified alone and its modes
    selected (as PoSER does), the references tested across setups, a
    :class:`ReferenceMismatchWarning` per rejection. None without uncertainty or with one reference.
    ``options`` are the setups' identification options; give them with
    :func:`reference_check_orders` of the merge's orders (the check does not need every order)."""
    if len(reference_names) < 2 or not options.uncertainty or len(core_setups) < 2:
        return None
    results = identify_each_setup(core_setups, options, record, names_per_setup, n_inputs_per_setup)
    selected = [select_modes(stabilization_diagram(res)) for res in results]
    opts = _core.PoserOptions()
    opts.reference_test_level = REFERENCE_TEST_LEVEL
    opts.min_setups = 2  # a mode seen in two setups can already be checked
    check = reference_check(poser_merge(selected, reference_names, options=opts), reference_names,
                            opts.reference_test_level)
    warn_reference_mismatch(check, stacklevel=4)
    return check

