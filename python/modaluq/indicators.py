"""Mode indicators with their uncertainty: MPC, MPD and the MAC between two shapes, each with the
standard deviation that follows from the shapes' covariance (the core's ``indicators.hpp``,
docs/uq-math.md §12), and the test "are these two estimates the same mode?" that reads it.

MPC and MAC are 1 at their maximum (a real mode; two estimates of one mode), where a first-order
σ would be 0 although the estimates scatter: the core propagates them to second order. A shape
covariance here is the ``(2l, 2l)`` covariance of ``[Re shape; Im shape]``: the lower-right block
of a mode's ``(2+2l, 2+2l)`` covariance of ``[f, ξ, Re shape, Im shape]``
(``SelectedModes.mode_covariance``, ``Modes.covariance``); :func:`shape_covariance` takes it out.

>>> import numpy as np
>>> shape = np.array([1.0, 0.5 + 0.02j, -0.3])
>>> round(modal_phase_collinearity(shape).value, 4)
0.999
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from . import _core

__all__ = ["IndicatorValue", "MacMatrix", "MacTest", "mac_matrix", "mac_test", "mean_phase_deviation",
           "modal_phase_collinearity", "shape_covariance"]


@dataclass(frozen=True)
class IndicatorValue:
    """An indicator of an estimated shape and its standard deviation (NaN without a covariance)."""

    value: float
    std: float


@dataclass(frozen=True)
class MacTest:
    """The MAC between two independently estimated shapes, its σ, and the test of "same mode".

    Under "same mode" (the true shapes collinear), ``1 - mac`` is a quadratic form of the
    estimation errors, with mean ``loss_mean`` and std ``loss_std`` (second order); ``p_value`` is
    its upper tail, from a scaled χ² with those two moments (Satterthwaite). A small ``p_value``
    says the shapes differ by more than their σ explain.
    """

    mac: float
    std: float              #: σ of the MAC estimate (second order)
    loss_mean: float        #: E[1 - MAC] if both estimate the same mode
    loss_std: float         #: its σ
    p_value: float          #: P(1 - MAC at least this large | same mode); NaN without covariances

    def same_mode(self, alpha: float = 0.01) -> bool:
        """True unless the test rejects "same mode" at level ``alpha`` (a MAC without σ: MAC ≥ 0.9)."""
        if not np.isfinite(self.p_value):
            return bool(self.mac >= 0.9)
        return bool(self.p_value >= alpha)


def shape_covariance(mode_covariance) -> np.ndarray:
    """The ``(2l, 2l)`` block of ``[Re shape; Im shape]`` of a mode's ``(2+2l, 2+2l)`` covariance
    of ``[f, ξ, Re shape, Im shape]``."""
    c = np.asarray(mode_covariance, dtype=float)
    if c.ndim != 2 or c.shape[0] != c.shape[1] or c.shape[0] < 4 or c.shape[0] % 2:
        raise ValueError(f"mode_covariance must be a (2+2l, 2+2l) covariance of [f, xi, Re shape, Im shape]; "
                         f"got shape {c.shape}")
    return c[2:, 2:]


def _shape(name: str, shape) -> np.ndarray:
    s = np.asarray(shape)
    if s.ndim != 1 or s.size == 0:
        raise ValueError(f"{name} must be a 1-D mode shape (one entry per channel); got shape {s.shape}")
    if not np.all(np.isfinite(s)):
        raise ValueError(f"{name} must be finite")
    if not np.any(s != 0):
        raise ValueError(f"{name} must not be zero")
    return s.astype(complex)


def _cov(name: str, cov, n: int) -> np.ndarray:
    try:
        c = np.asarray(cov, dtype=float)
    except (TypeError, ValueError) as e:
        raise TypeError(f"{name} must be a real covariance matrix; got {type(cov).__name__}") from e
    if not np.all(np.isfinite(c)):
        raise ValueError(f"{name} must be finite")
    if c.shape != (2 * n, 2 * n):
        raise ValueError(f"{name} must be the ({2 * n}, {2 * n}) covariance of [Re shape; Im shape] of a "
                         f"{n}-component shape; got shape {c.shape}")
    return c


def modal_phase_collinearity(shape, cov=None) -> IndicatorValue:
    """MPC of ``shape`` (1: real, 0: circular), with its σ from ``cov`` (second order)."""
    s = _shape("shape", shape)
    if cov is None:
        return IndicatorValue(float(_core.modal_phase_collinearity(s)), float("nan"))
    r = _core.modal_phase_collinearity_statistics(s, _cov("cov", cov, s.size))
    return IndicatorValue(float(r.value), float(r.std))


def mean_phase_deviation(shape, cov=None) -> IndicatorValue:
    """MPD of ``shape`` in degrees (0: real, up to 90), with its first-order σ from ``cov``.

    The deviations are absolute angles: for a nearly real shape the estimate is folded at 0 and
    its σ (of the signed angles) describes the spread of those, not a symmetric interval."""
    s = _shape("shape", shape)
    r = _core.mean_phase_deviation(s, np.zeros((0, 0)) if cov is None else _cov("cov", cov, s.size))
    return IndicatorValue(float(r.value), float(r.std))


def mac_test(shape_a, shape_b, cov_a=None, cov_b=None, cross_covariance=None) -> MacTest:
    """MAC of two estimated shapes with its σ and the "same mode" test: two records, two setups, or
    an estimate against a fixed reference (leave that one's covariance ``None``), taken as
    independent; or two modes of ONE identification, which share the data, with their
    ``cross_covariance``, the ``(2l, 2l)`` covariance of ``[Re a; Im a]`` with ``[Re b; Im b]``
    (``V_a V_bᵀ`` of their shape factors, ``identify(..., keep_shape_factor=True)``).

    Both covariances ``None``: the MAC alone (σ and p-value NaN)."""
    a, b = _shape("shape_a", shape_a), _shape("shape_b", shape_b)
    if a.size != b.size:
        raise ValueError(f"shape_a and shape_b must have as many components; got {a.size} and {b.size}")
    if cov_a is None and cov_b is None:
        if cross_covariance is not None:
            raise ValueError("cross_covariance needs cov_a and cov_b")
        nan = float("nan")
        return MacTest(float(_core.modal_assurance(a, b)), nan, nan, nan, nan)
    zero = np.zeros((2 * a.size, 2 * a.size))
    ca = zero if cov_a is None else _cov("cov_a", cov_a, a.size)
    cb = zero if cov_b is None else _cov("cov_b", cov_b, b.size)
    if cross_covariance is None:
        r = _core.modal_assurance_statistics(a, ca, b, cb)
    else:
        c = _cov("cross_covariance", cross_covariance, a.size)
        joint = np.block([[ca, c], [c.T, cb]])
        r = _core.modal_assurance_statistics_joint(a, b, 0.5 * (joint + joint.T))
    return MacTest(float(r.value), float(r.std), float(r.loss_at_maximum_mean), float(r.loss_at_maximum_std),
                   _loss_p_value(1.0 - float(r.value), float(r.loss_at_maximum_mean), float(r.loss_at_maximum_std)))


def _loss_p_value(loss: float, mean: float, std: float) -> float:
    """Upper tail of a loss under the maximum: a χ² scaled to the loss's mean and std."""
    if not (mean > 0 and std > 0):
        return float("nan")
    from scipy.stats import chi2  # lazy: import modaluq stays light

    scale, dof = std * std / (2 * mean), 2 * mean * mean / (std * std)
    return float(chi2.sf(max(loss, 0.0) / scale, dof))


@dataclass(frozen=True)
class MacMatrix:
    """The MAC between every pair of a set of shapes (an AutoMAC) and its σ (second order)."""

    mac: np.ndarray  #: (m, m), symmetric, 1 on the diagonal
    #: (m, m) σ of each MAC (see :func:`mac_matrix`); 0 on the diagonal (a shape's MAC with itself
    #: is 1 exactly); NaN without covariances
    std: np.ndarray
    #: True: the σ treat the shapes as independent (no factors given), which two modes of one
    #: identification are not; False: their cross-covariance from the factors is included
    independent_approximation: bool


def mac_matrix(shapes, covariances=None, factors=None) -> MacMatrix:
    """AutoMAC of the columns of ``shapes`` (l, m) with the σ of each entry (second order, as
    :func:`mac_test`).

    Parameters
    ----------
    shapes : (l, m) complex
    covariances : optional, (m, 2l, 2l) of [Re shape, Im shape], or the modes' (m, 2+2l, 2+2l) of
        [f, ξ, Re shape, Im shape] (``SelectedModes.mode_covariance``).
    factors : optional, (m, 2l, n_blocks), each shape's first-order factor V (covariance V Vᵀ;
        ``SelectedModes.mode_shape_factor``, kept with ``identify(..., keep_shape_factor=True)``).
        Two modes of one identification share the data, so the σ of their MAC needs the
        cross-covariance V_i V_jᵀ of their shapes: with ``factors`` it is included (to first
        order, as each pole's own σ; the covariances are then V Vᵀ and ``covariances`` is ignored).

    Without ``factors`` the cross-covariance is taken as 0, as for shapes of two independent
    records (``independent_approximation``): against the σ with it this is within about ±20 % on
    the simulated chain (docs/shapes.md §6). The MAC values themselves are exact either way."""
    phi = np.asarray(shapes)
    if phi.ndim != 2 or 0 in phi.shape:
        raise ValueError(f"shapes must be (n_channels, n_modes) with at least one of each; got shape {phi.shape}")
    phi = np.column_stack([_shape(f"shapes[:, {k}]", phi[:, k]) for k in range(phi.shape[1])])
    l, m = phi.shape
    mac = np.asarray(_core.modal_assurance_criterion(phi, phi), float)
    mac = 0.5 * (mac + mac.T)
    np.fill_diagonal(mac, 1.0)
    std = np.full((m, m), np.nan)
    if factors is not None:
        v = np.asarray(factors, dtype=float)
        if v.ndim != 3 or v.shape[:2] != (m, 2 * l) or v.shape[2] < 1:
            raise ValueError(f"factors must be ({m}, {2 * l}, n_blocks) shape factors of {m} shapes of {l} "
                             f"channels; got shape {v.shape}")
        if not np.isfinite(v).all():
            raise ValueError("factors must be finite")

        def pair_std(i, j):  # the two shapes share the data: their cross-covariance V_i V_jᵀ
            return mac_test(phi[:, i], phi[:, j], v[i] @ v[i].T, v[j] @ v[j].T, cross_covariance=v[i] @ v[j].T).std
    elif covariances is not None:
        c = np.asarray(covariances, dtype=float)
        if c.ndim != 3 or c.shape[0] != m or c.shape[1:] not in ((2 * l, 2 * l), (2 + 2 * l, 2 + 2 * l)):
            raise ValueError(f"covariances must be ({m}, {2 * l}, {2 * l}) shape covariances or ({m}, {2 + 2 * l}, "
                             f"{2 + 2 * l}) mode covariances of {m} shapes of {l} channels; got shape {c.shape}")
        if c.shape[1] == 2 + 2 * l:
            c = c[:, 2:, 2:]
        c = np.stack([_cov(f"covariances[{k}]", c[k], l) for k in range(m)])

        def pair_std(i, j):
            return _core.modal_assurance_statistics(phi[:, i], c[i], phi[:, j], c[j]).std
    else:
        return MacMatrix(mac=mac, std=std, independent_approximation=True)
    std[np.diag_indices(m)] = 0.0
    for i in range(m):
        for j in range(i + 1, m):
            std[i, j] = std[j, i] = float(pair_std(i, j))
    return MacMatrix(mac=mac, std=std, independent_approximation=factors is None)
