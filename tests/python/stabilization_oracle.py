"""The stabilization and selection as they were written in Python before they moved to the C++ core
(cpp/include/modaluq/stabilization.hpp, selection.hpp): an independent reference for the core.

The diagram is NumPy; the clustering is SciPy's ``linkage`` + ``fcluster``, so the core's
nearest-neighbour-chain clustering is checked against a different implementation.
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np

from modaluq import ClusteringSettings, Diagram, PoleStatus, SelectedModes, StabilityCriteria


def modal_assurance_criterion(shape_a, shape_b) -> np.ndarray:
    """MAC in NumPy (modaluq's is the core's): |a_iᴴ b_j|² / ((a_iᴴ a_i)(b_jᴴ b_j)), 0 for a zero shape."""
    a = np.asarray(shape_a)
    b = np.asarray(shape_b)
    a = a[:, None] if a.ndim == 1 else a
    b = b[:, None] if b.ndim == 1 else b
    cross = np.abs(a.conj().T @ b) ** 2
    denom = np.outer(np.real(np.sum(a.conj() * a, axis=0)), np.real(np.sum(b.conj() * b, axis=0)))
    with np.errstate(invalid="ignore", divide="ignore"):
        mac = np.where(denom > 0, cross / np.where(denom > 0, denom, 1.0), 0.0)
    return np.clip(mac, 0.0, 1.0)


def _pct(x: float) -> str:
    return f"{100 * x:.3g} %"


def _pole_checks(f, xi, sf, c: StabilityCriteria, has_std: bool) -> list:
    reasons = []
    if xi < c.min_damping_ratio:
        reasons.append(f"damping ratio {_pct(xi)} < {_pct(c.min_damping_ratio)}")
    if xi > c.max_damping_ratio:
        reasons.append(f"damping ratio {_pct(xi)} > {_pct(c.max_damping_ratio)}")
    if has_std and c.max_frequency_cov is not None:
        if not np.isfinite(sf):
            reasons.append("frequency std not finite")
        elif sf / f > c.max_frequency_cov:
            reasons.append(f"frequency std/f {_pct(sf / f)} > {_pct(c.max_frequency_cov)}")
    return reasons


def stabilization_diagram_reference(result, criteria: StabilityCriteria | None = None, *,
                          output_names=None, **kwargs) -> Diagram:
    """Judge every pole of a multi-order identification (see :class:`StabilityCriteria`).

    Parameters
    ----------
    result : modaluq.Result
        From :func:`modaluq.identify` with several orders (``orders=range(2, 61, 2)``...).
    criteria : StabilityCriteria, optional
        Thresholds; default ``StabilityCriteria()``. Alternatively pass its fields as keyword
        arguments (``max_frequency_change=0.02``...).
    output_names : sequence of str, optional
        One name per output channel (default ``y0, y1, ...``), used in tables, plots and exports.

    Returns
    -------
    Diagram
        Every pole with its :class:`PoleStatus` and, for the others than stable, the reason.
    """
    from modaluq.results import Result

    if not isinstance(result, Result):
        raise TypeError(f"result must be a modaluq.Result (from modaluq.identify); got {type(result).__name__}")
    if criteria is None:
        criteria = StabilityCriteria(**kwargs)
    elif kwargs:
        raise TypeError("pass either criteria= or its fields as keyword arguments, not both")
    elif not isinstance(criteria, StabilityCriteria):
        raise TypeError(f"criteria must be a StabilityCriteria; got {type(criteria).__name__}")
    n_out = int(result.n_outputs)
    if output_names is None:
        names = tuple(f"y{k}" for k in range(n_out))
    else:
        names = tuple(str(s) for s in output_names)
        if len(names) != n_out:
            raise ValueError(f"output_names must have {n_out} entries (one per output); got {len(names)}")
    has_std = all(m.has_uncertainty for m in result.modes)
    c = criteria
    k_std = c.frequency_std_factor if has_std else None

    cols = {k: [] for k in ("order", "f", "xi", "sf", "sxi", "close", "coupled")}
    shapes, shapes_sr, shapes_si = [], [], []
    for m in result.modes:
        n = m.n_modes
        cols["order"].append(np.full(n, m.order, dtype=np.int64))
        cols["f"].append(np.asarray(m.frequency_hz, float))
        cols["xi"].append(np.asarray(m.damping_ratio, float))
        nan = np.full(n, np.nan)
        cols["sf"].append(np.asarray(m.frequency_std, float) if m.has_uncertainty else nan)
        cols["sxi"].append(np.asarray(m.damping_std, float) if m.has_uncertainty else nan)
        cols["close"].append(np.full(n, bool(m.close_singular_values)))
        coupled = getattr(m, "noise_coupled", None)
        cols["coupled"].append(np.zeros(n, bool) if coupled is None else np.asarray(coupled, bool).reshape(n))
        shapes.append(np.asarray(m.mode_shape, complex).reshape(n_out, n))
        nan2 = np.full((n_out, n), np.nan)
        shapes_sr.append(np.asarray(m.mode_shape_std_real, float).reshape(n_out, n) if m.has_uncertainty else nan2)
        shapes_si.append(np.asarray(m.mode_shape_std_imag, float).reshape(n_out, n) if m.has_uncertainty else nan2)
    order = np.concatenate(cols["order"])
    f = np.concatenate(cols["f"])
    xi = np.concatenate(cols["xi"])
    sf = np.concatenate(cols["sf"])
    sxi = np.concatenate(cols["sxi"])
    close = np.concatenate(cols["close"])
    coupled = np.concatenate(cols["coupled"])
    # each pole's factor rows [u_f, u_xi] (n_poles, 2, n_b), when every order with poles has them
    rows = [m.frequency_damping_factor for m in result.modes if m.n_modes]
    factor = (np.concatenate(rows) if rows and all(u is not None for u in rows) else np.zeros((0, 2, 0)))
    shape = np.concatenate(shapes, axis=1)
    n_poles = f.size

    status = np.empty(n_poles, dtype=object)
    reason = np.empty(n_poles, dtype=object)
    matched = np.full(n_poles, -1, dtype=np.int64)
    df = np.full(n_poles, np.nan)
    dxi = np.full(n_poles, np.nan)
    mac = np.full(n_poles, np.nan)
    dz = np.full(n_poles, np.nan)

    # The band of interest given to identify (frequency_range): poles outside it are rejected.
    band = result.settings.get("frequency_range") if isinstance(result.settings, dict) else None
    valid = np.zeros(n_poles, dtype=bool)
    for i in range(n_poles):
        r = _pole_checks(f[i], xi[i], sf[i], c, has_std)
        if band is not None and not band[0] <= f[i] <= band[1]:
            r = [f"outside the band {band[0]:g}-{band[1]:g} Hz"] + r
        if r:
            status[i], reason[i] = PoleStatus.REJECTED, "; ".join(r)
        valid[i] = not r

    orders = tuple(int(m.order) for m in result.modes)
    for j, n in enumerate(orders):
        cur = np.flatnonzero((order == n) & valid)
        if j == 0:
            for i in cur:
                status[i], reason[i] = PoleStatus.UNSTABLE, "lowest order: no previous order to compare"
            continue
        prev = np.flatnonzero((order == orders[j - 1]) & valid)
        if prev.size == 0:
            for i in cur:
                status[i], reason[i] = PoleStatus.UNSTABLE, f"no accepted pole at the previous order {orders[j - 1]}"
            continue
        if cur.size == 0:
            continue
        mac_cp = modal_assurance_criterion(shape[:, cur], shape[:, prev])
        rel_cp = np.abs(f[cur][:, None] - f[prev][None, :]) / f[prev][None, :]
        cost = np.where(rel_cp <= c.match_window, rel_cp + (1.0 - mac_cp), np.inf)
        best = np.argmin(cost, axis=1)  # first minimum: deterministic
        for a, i in enumerate(cur):
            if not np.isfinite(cost[a, best[a]]):  # nothing of the previous order nearby
                status[i] = PoleStatus.UNSTABLE
                reason[i] = (f"no match: no pole within {_pct(c.match_window)} in frequency at the previous "
                             f"order {orders[j - 1]}")
                continue
            p = prev[best[a]]
            matched[i] = p
            df[i] = rel_cp[a, best[a]]
            mac[i] = mac_cp[a, best[a]]
            dxi[i] = abs(xi[i] - xi[p]) / abs(xi[p]) if xi[p] != 0 else (0.0 if xi[i] == 0 else np.inf)
            why = []
            if df[i] > c.max_frequency_change:
                why.append(f"frequency change {_pct(df[i])} > {_pct(c.max_frequency_change)}")
            if k_std is not None:
                comb = math.hypot(sf[i], sf[p])
                dz[i] = abs(f[i] - f[p]) / comb if comb > 0 else np.inf
                if dz[i] > k_std:
                    why.append(f"frequency change {abs(f[i] - f[p]):.3g} Hz > {k_std:g} x combined std "
                               f"{comb:.3g} Hz")
            if why:
                status[i] = PoleStatus.UNSTABLE
            else:
                k_xi = c.damping_std_factor if has_std else None
                comb_xi = math.hypot(sxi[i], sxi[p]) if k_xi is not None else np.nan
                if k_xi is not None and np.isfinite(comb_xi):
                    if abs(xi[i] - xi[p]) > k_xi * comb_xi:
                        why.append(f"damping change {abs(xi[i] - xi[p]):.3g} > {k_xi:g} x combined std {comb_xi:.3g}")
                    elif dxi[i] > c.max_damping_change_with_std:
                        why.append(f"damping change {_pct(dxi[i])} > {_pct(c.max_damping_change_with_std)}")
                elif dxi[i] > c.max_damping_change:
                    why.append(f"damping change {_pct(dxi[i])} > {_pct(c.max_damping_change)}")
                if mac[i] < c.min_mac:
                    why.append(f"MAC {mac[i]:.4f} < {c.min_mac:g}")
                status[i] = PoleStatus.STABLE_FREQUENCY if why else PoleStatus.STABLE
            reason[i] = ("; ".join(why) + f" (vs order {orders[j - 1]})") if why else ""

    return Diagram(
        order=order, frequency_hz=f, damping_ratio=xi, frequency_std=sf, damping_std=sxi,
        mode_shape=shape, mode_shape_std_real=np.concatenate(shapes_sr, axis=1),
        mode_shape_std_imag=np.concatenate(shapes_si, axis=1), status=status,
        reason=reason.astype(str) if n_poles else np.array([], dtype=str), matched_pole=matched,
        frequency_change=df, damping_change=dxi, mac=mac, frequency_change_std=dz,
        close_singular_values=close, noise_coupled=coupled, orders=orders, fs=float(result.fs), output_names=names,
        criteria=c, has_uncertainty=has_std, result_settings=dict(result.settings),
        frequency_damping_factor=factor, noise_floor_order=int(getattr(result, "significant_singular_values", 0)),
    )


def _default_min_cluster_size(diagram: Diagram, in_set: np.ndarray, fraction: float) -> int:
    if not in_set.any():
        return 3
    first = int(diagram.order[in_set].min())
    n_after = sum(1 for n in diagram.orders if n >= first)
    return max(3, int(math.ceil(fraction * n_after - 1e-9)))


def _merge_fragments(clusters, diagram, thin, settings):
    """Join pieces of one mode: largest first (ties: lowest first pole), within
    fragment_std_factor combined σ, MAC >= fragment_min_mac, few orders shared; until none joins."""
    f = diagram.frequency_hz
    clusters = [np.sort(np.asarray(c, dtype=np.int64)) for c in clusters]

    def summary(c):
        one = thin(c)
        med = float(np.median(f[one]))
        sd = diagram.frequency_std[one]
        sd = sd[np.isfinite(sd)]
        rep = one[np.argmin(np.abs(f[one] - med))]
        return med, float(np.median(sd)) if sd.size else 0.0, rep, set(diagram.order[one].tolist()), one.size

    joined = True
    while joined:
        joined = False
        clusters.sort(key=lambda c: (-c.size, int(c[0])))
        sums = [summary(c) for c in clusters]
        for a in range(len(clusters)):
            for b in range(a + 1, len(clusters)):
                fa, sa, ra, oa, na = sums[a]
                fb, sb, rb, ob, nb = sums[b]
                if not abs(fa - fb) <= settings.fragment_std_factor * math.hypot(sa, sb):
                    continue
                if modal_assurance_criterion(diagram.mode_shape[:, ra], diagram.mode_shape[:, rb])[0, 0] < \
                        settings.fragment_min_mac:
                    continue
                if len(oa & ob) > settings.fragment_max_shared * min(na, nb):
                    continue
                clusters[a] = np.sort(np.concatenate([clusters[a], clusters[b]]))
                del clusters[b]
                joined = True
                break
            if joined:
                break
    return clusters


def _twin_view(m, diagram):
    """(median f, median ξ, first order, the pole nearest the median f) of a kept cluster, as the twin rules read it."""
    f = diagram.frequency_hz
    med = float(np.median(f[m]))
    return med, float(np.median(diagram.damping_ratio[m])), int(diagram.order[m].min()), m[np.argmin(np.abs(f[m] - med))]


def _reassign_borrowed_poles(kept, diagram, settings):
    """Of two alike clusters (doublet_window, MAC >= doublet_min_mac of their median-nearest poles),
    the earlier one's poles below the later one's first order go to the later one when each is
    nearer to its median f and median ξ; medians and first orders from before any move, clusters
    in order of (first order, first pole), each giving or taking once. Returns the clusters (one
    left empty if all its poles moved) and which gave or took."""
    f, xi, order = diagram.frequency_hz, diagram.damping_ratio, diagram.order
    info = [_twin_view(m, diagram) for m in kept]
    by_first = sorted(range(len(kept)), key=lambda k: (info[k][2], int(kept[k][0])))
    kept = list(kept)
    involved = np.zeros(len(kept), dtype=bool)
    for b in by_first:
        if involved[b]:
            continue
        fb, xb, first_b, rep_b = info[b]
        for a in by_first:
            fa, xa, first_a, rep_a = info[a]
            if a == b or involved[a] or first_a <= first_b or abs(fa - fb) / max(fa, fb) > settings.doublet_window:
                continue
            mac = modal_assurance_criterion(diagram.mode_shape[:, rep_a], diagram.mode_shape[:, rep_b])[0, 0]
            if mac < settings.doublet_min_mac:
                continue
            lead = kept[b][order[kept[b]] < first_a]
            if not np.all((np.abs(f[lead] - fa) < np.abs(f[lead] - fb)) & (np.abs(xi[lead] - xa) < np.abs(xi[lead] - xb))):
                continue
            kept[b] = kept[b][order[kept[b]] >= first_a]
            kept[a] = np.sort(np.concatenate([kept[a], lead]))
            involved[[a, b]] = True
            break
    return kept, involved


def _drop_doublets(kept, diagram, settings, dropped):
    """In order of (first order, -size, first pole), against each earlier survivor in turn:
    drop_noise_twins drops a cluster born above the noise floor k*, later than the survivor,
    less than half as damped and inside its half-power band |f - f_s| < f_s ξ_s (median f and ξ);
    drop_doublets one within doublet_window whose median-nearest pole has MAC >= doublet_min_mac
    with the survivor's."""
    k_star = diagram.noise_floor_order
    noise_twins = settings.drop_noise_twins and diagram.has_uncertainty and k_star > 0
    def mac_of(a, b):
        return modal_assurance_criterion(diagram.mode_shape[:, a], diagram.mode_shape[:, b])[0, 0]

    items = []
    for m in kept:
        med, med_xi, first, rep = _twin_view(m, diagram)
        items.append((first, -m.size, int(m[0]), med, med_xi, rep, m))
    items.sort(key=lambda t: t[:3])
    survivors, out = [], []
    for first, neg_n, _, med, med_xi, rep, m in items:
        reason = None
        for s_first, s_med, s_xi, s_rep in survivors:
            mac = mac_of(rep, s_rep)
            if (noise_twins and first > k_star and first > s_first and med_xi < 0.5 * s_xi
                    and abs(med - s_med) < s_med * s_xi):
                reason = (f"a lightly damped twin of the {s_med:.4g} Hz mode born of the noise: less than half as "
                          f"damped, inside its half-power band ({100 * abs(med - s_med) / s_med:.3g} % away), from order "
                          f"{first} above the noise floor (the mode from order {s_first})")
                break
            if not settings.drop_doublets or abs(med - s_med) / max(med, s_med) > settings.doublet_window:
                continue
            if mac >= settings.doublet_min_mac:
                reason = (f"a twin of the {s_med:.4g} Hz mode: same shape (MAC {mac:.2f}), "
                          f"{100 * abs(med - s_med) / s_med:.3g} % away, from order {first} (the mode from order {s_first})")
                break
        if reason is None:
            survivors.append((first, med, med_xi, rep))
            out.append(m)
        else:
            dropped.append((med, -neg_n, reason))
    return out


def select_modes_reference(diagram: Diagram, settings: ClusteringSettings | None = None, **kwargs) -> SelectedModes:
    """The selection written with SciPy's clustering (see modaluq.select_modes for the rules)."""
    import scipy.cluster.hierarchy as sch
    from scipy.spatial.distance import squareform

    if not isinstance(diagram, Diagram):
        raise TypeError(f"diagram must be a Diagram (from stabilization_diagram); got {type(diagram).__name__}")
    if settings is None:
        settings = ClusteringSettings(**kwargs)
    elif kwargs:
        raise TypeError("pass either settings= or its fields as keyword arguments, not both")
    elif not isinstance(settings, ClusteringSettings):
        raise TypeError(f"settings must be a ClusteringSettings; got {type(settings).__name__}")

    # None: the mean for the diagram of a multi-setup merge (its settings list the setups)
    cluster_std = settings.cluster_std or ("mean" if diagram.result_settings.get("setups") else "median")
    settings = dataclasses.replace(settings, cluster_std=cluster_std)
    factor = diagram.frequency_damping_factor
    in_set = np.zeros(diagram.n_poles, dtype=bool)
    for s in settings.statuses:
        in_set |= diagram.is_status(s)
    min_size = settings.min_cluster_size or _default_min_cluster_size(diagram, in_set,
                                                                     settings.min_cluster_fraction)
    idx = np.flatnonzero(in_set)
    f, xi, order = diagram.frequency_hz, diagram.damping_ratio, diagram.order
    shape = diagram.mode_shape

    clusters = []
    if idx.size == 1:
        clusters = [idx]
    elif idx.size > 1:
        fi = f[idx]
        dist = np.abs(fi[:, None] - fi[None, :]) / np.maximum(fi[:, None], fi[None, :])
        dist += 1.0 - modal_assurance_criterion(shape[:, idx], shape[:, idx])
        np.fill_diagonal(dist, 0.0)
        dist = 0.5 * (dist + dist.T)
        z = sch.linkage(squareform(dist, checks=False), method=settings.linkage)
        labels = sch.fcluster(z, t=settings.distance_threshold, criterion="distance")
        for lab in np.unique(labels):
            clusters.append(idx[labels == lab])

    def std_per_bandwidth(m):
        with np.errstate(divide="ignore", invalid="ignore"):
            q = np.where(xi[m] > 0, diagram.frequency_std[m] / (f[m] * np.where(xi[m] > 0, xi[m], 1.0)), np.inf)
        return float(np.median(q))

    check_bandwidth = settings.max_frequency_std_per_bandwidth is not None and diagram.has_uncertainty
    smallest = min_size
    def thin(members):
        # one pole per order: the one nearest to the median frequency (ties: lower index)
        med = np.median(f[members])
        keep = []
        for n in np.unique(order[members]):
            at_n = members[order[members] == n]
            keep.append(at_n[np.argmin(np.abs(f[at_n] - med))])
        return np.sort(np.asarray(keep, dtype=np.int64))

    if settings.merge_fragments and diagram.has_uncertainty:
        clusters = _merge_fragments(clusters, diagram, thin, settings)
    kept, dropped = [], []
    smallest = [smallest]

    def judge(members):
        """The size and bandwidth rules: True if kept, else the reason is in dropped."""
        need = min_size
        if settings.min_cluster_size is None and settings.per_cluster_min_size:
            first = int(order[members].min())
            need = max(3, int(math.ceil(settings.min_cluster_fraction * sum(1 for n in diagram.orders if n >= first)
                                        - 1e-9)))
            smallest[0] = min(smallest[0], need)
        if members.size < need:
            dropped.append((float(np.median(f[members])), members.size, f"{members.size} pole{'' if members.size == 1 else 's'}, fewer than {need}"))
        elif check_bandwidth and not std_per_bandwidth(members) <= settings.max_frequency_std_per_bandwidth:
            q = std_per_bandwidth(members)
            dropped.append((float(np.median(f[members])), members.size,
                            f"frequency std {q:.3g} x the half-power bandwidth f xi (more than "
                            f"{settings.max_frequency_std_per_bandwidth:g})"))
        else:
            return True
        return False

    kept = [m for m in map(thin, clusters) if judge(m)]
    if settings.drop_doublets and settings.reassign_borrowed_poles:
        # the clusters that gave or took are judged again; one that gave all its poles is gone
        moved, involved = _reassign_borrowed_poles(kept, diagram, settings)
        kept = [m for m, again in zip(moved, involved) if m.size and (not again or judge(m))]
    smallest = smallest[0]
    if settings.drop_doublets or settings.drop_noise_twins:
        kept = _drop_doublets(kept, diagram, settings, dropped)
    kept.sort(key=lambda m: float(np.median(f[m])))
    dropped.sort()
    n_out = diagram.n_outputs
    n_modes = len(kept)
    rep = np.zeros(n_modes, dtype=np.int64)
    sp = np.zeros(n_modes, dtype=np.int64)
    f_spread = np.zeros(n_modes)
    xi_spread = np.zeros(n_modes)
    sh_spread_r = np.zeros((n_out, n_modes))
    sh_spread_i = np.zeros((n_out, n_modes))
    min_mac = np.zeros(n_modes)
    sf_med = np.full(n_modes, np.nan)
    sxi_med = np.full(n_modes, np.nan)
    rho = np.full(n_modes, np.nan)
    widened = np.zeros(n_modes, dtype=bool)
    unanchored = np.zeros(n_modes, dtype=bool)
    mode_of_pole = np.full(diagram.n_poles, -1, dtype=np.int64)
    for k, members in enumerate(kept):
        mode_of_pole[members] = k
        med = np.median(f[members])
        # the representative's σ is read from it: not at a cut inside a cluster, not noise-coupled
        # (unless most of the cluster is: then the coupled poles count, with their unfrozen σ)
        mostly = 2 * diagram.noise_coupled[members].sum() > members.size
        coupled = diagram.noise_coupled[members] & ~mostly
        candidates = members[~(diagram.close_singular_values[members] | coupled)]
        if candidates.size == 0:
            candidates = members
        ddof = 1 if members.size > 1 else 0
        f_spread[k] = np.std(f[members], ddof=ddof)
        xi_spread[k] = np.std(xi[members], ddof=ddof)
        finite = np.isfinite(diagram.frequency_std[members]) & np.isfinite(diagram.damping_std[members])
        unflagged = ~(diagram.close_singular_values[members] | coupled)
        reliable, with_std = members[finite & unflagged], members[finite]

        def scale(std, spread):
            x = (np.median(std[reliable]) if reliable.size else np.median(std[with_std]) if with_std.size
                 else spread)
            return x if np.isfinite(x) and x > 0 else 1.0

        sc_f = scale(diagram.frequency_std, f_spread[k])
        sc_xi = scale(diagram.damping_std, xi_spread[k])
        dist = ((f[candidates] - med) / sc_f) ** 2 + ((xi[candidates] - np.median(xi[members])) / sc_xi) ** 2
        rep[k] = candidates[np.flatnonzero(dist == dist.min())[-1]]  # ties -> the higher order
        # the lowest sufficient member: the lowest order >= max(k*, 2 m), else the highest
        above = candidates[order[candidates] >= max(diagram.noise_floor_order, 2 * n_modes)]
        lowest_member = above.min() if above.size else candidates.max()
        lowest = settings.representative == "lowest"
        if lowest:  # the mode is that pole, its own sigma included
            rep[k] = lowest_member
            sf_med[k], sxi_med[k] = diagram.frequency_std[rep[k]], diagram.damping_std[rep[k]]
            if diagram.frequency_damping_correlation.size == diagram.n_poles:
                rho[k] = diagram.frequency_damping_correlation[rep[k]]
        elif reliable.size and cluster_std == "mean" and factor.shape[0] == diagram.n_poles:
            # the sigma of the reliable poles' mean: its factor rows are the mean of theirs
            u = factor[reliable].mean(axis=0)
            sf_med[k], sxi_med[k] = np.linalg.norm(u[0]), np.linalg.norm(u[1])
            rho[k] = u[0] @ u[1] / (sf_med[k] * sxi_med[k]) if sf_med[k] > 0 and sxi_med[k] > 0 else np.nan
        else:
            if reliable.size:
                sf_med[k] = np.median(diagram.frequency_std[reliable])
                sxi_med[k] = np.median(diagram.damping_std[reliable])
            else:
                sf_med[k], sxi_med[k] = diagram.frequency_std[rep[k]], diagram.damping_std[rep[k]]
            if diagram.frequency_damping_correlation.size == diagram.n_poles:
                rho[k] = diagram.frequency_damping_correlation[rep[k]]
        # a mode with no order below its own noise floor: every reliable pole's rho above the limit
        # gives the mode at least their median rho sigma (the unfrozen bound)
        limit = settings.unanchored_noise_coupling
        rhos = diagram.noise_coupling
        if limit is not None and rhos.size == diagram.n_poles and not mostly and reliable.size \
                and np.all(rhos[reliable] > limit):
            sf_med[k] = max(sf_med[k], np.median(rhos[reliable] * diagram.frequency_std[reliable]))
            sxi_med[k] = max(sxi_med[k], np.median(rhos[reliable] * diagram.damping_std[reliable]))
            unanchored[k] = True
        # the shape pole (shape_representative "lowest"): the lowest sufficient member, unless the
        # representative is lower and holds every selected mode (order >= 2 m)
        keep_rep = diagram.order[rep[k]] >= 2 * n_modes and diagram.order[lowest_member] >= diagram.order[rep[k]]
        sufficient = rep[k] if keep_rep else lowest_member
        sp[k] = sufficient if settings.shape_representative == "lowest" else rep[k]
        if settings.order_discrepancy and sufficient != rep[k]:
            # the representative against the lowest sufficient member: a difference beyond 1.96 of
            # their combined σ is the model order's, added to the mode's σ
            for sig, v, own in ((sf_med, f, diagram.frequency_std), (sxi_med, xi, diagram.damping_std)):
                d = v[rep[k]] - v[sufficient]
                if abs(d) > 1.96 * np.hypot(own[rep[k]], own[sufficient]):  # the two poles' own σ
                    sig[k] = np.hypot(sig[k], d)
                    widened[k] = True
        ref = int(np.argmax(np.abs(shape[:, sp[k]])))
        aligned = shape[:, members] / shape[ref, members][None, :]
        sh_spread_r[:, k] = np.std(aligned.real, axis=1, ddof=ddof)
        sh_spread_i[:, k] = np.std(aligned.imag, axis=1, ddof=ddof)
        min_mac[k] = modal_assurance_criterion(shape[:, sp[k]], shape[:, members]).min()

    def empty_if_none(a):
        return a if a.size else np.zeros(0)

    return SelectedModes(
        frequency_hz=f[rep], damping_ratio=xi[rep], mode_shape=shape[:, sp],
        frequency_std=sf_med, damping_std=sxi_med,
        mode_shape_std_real=diagram.mode_shape_std_real[:, sp],
        mode_shape_std_imag=diagram.mode_shape_std_imag[:, sp],
        frequency_spread=f_spread, damping_spread=xi_spread,
        mode_shape_spread_real=sh_spread_r, mode_shape_spread_imag=sh_spread_i,
        min_mac=min_mac, representative_order=order[rep], representative_pole=rep, shape_pole=sp,
        shape_order=order[sp],
        n_poles=np.array([m.size for m in kept], dtype=np.int64),
        order_min=np.array([order[m].min() for m in kept], dtype=np.int64),
        order_max=np.array([order[m].max() for m in kept], dtype=np.int64),
        members=tuple(kept), mode_of_pole=mode_of_pole,
        dropped_frequency_hz=empty_if_none(np.array([d[0] for d in dropped])),
        dropped_n_poles=np.array([d[1] for d in dropped], dtype=np.int64),
        dropped_reason=tuple(d[2] for d in dropped),
        frequency_std_per_bandwidth=np.array([std_per_bandwidth(m) if diagram.has_uncertainty else np.nan
                                              for m in kept]),
        min_cluster_size=int(smallest), output_names=diagram.output_names, settings=settings,
        has_uncertainty=diagram.has_uncertainty, frequency_damping_correlation=rho, order_discrepancy=widened,
        unanchored=unanchored,
    )
