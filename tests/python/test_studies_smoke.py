"""The studies of ``studies/`` still run with the package's API: each on a tiny configuration.

They print the tables that the docs quote (studies/README.md); here only that they run to the
end (a renamed function or argument breaks them), not their numbers. The shared records are
read from ``../shared/data`` beside the repository (or ``$MODALUQ_SHARED_DATA``); the runs that
need them are skipped without.
"""

import importlib.util
import os
import pathlib
import runpy
import shutil
import sys
import warnings

import numpy as np
import pytest

ROOT = pathlib.Path(__file__).resolve().parents[2]
STUDIES = ROOT / "studies"
HIGH_ORDERS = STUDIES / "high_orders"
DATA = pathlib.Path(os.environ.get("MODALUQ_SHARED_DATA", ROOT.parent / "shared" / "data"))
needs_data = pytest.mark.skipif(not (DATA / "cesmd_meloland_overpass_2016.npz").exists(),
                                reason=f"the shared records are not in {DATA}")


def _module(name):
    spec = importlib.util.spec_from_file_location(f"studies_{name}", STUDIES / f"{name}.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def _script(monkeypatch, name, *args):
    """Run ``studies/high_orders/<name>`` as ``python <name> args...`` in this process."""
    monkeypatch.setattr(sys, "argv", [name, *map(str, args)])
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # the scripts' statistics of 2 records are NaN here and there
        runpy.run_path(str(HIGH_ORDERS / name), run_name="__main__")


def test_every_study_is_smoke_tested():
    scripts = {p.name for p in HIGH_ORDERS.glob("*.py")} | {p.name for p in STUDIES.glob("*.py")}
    tested = set(HIGH_ORDER_RUNS) | {"prop.py", "earthquake_records.py", "settings_records.py", "selected_sigma_mc.py",
                                           "indicators_mc.py", "multisetup_mc.py", "automac_mc.py",
                                           "warnings_issue27.py", "warnings_issue27_premise.py",
                                           "io_block_bias.py", "poser_mc.py", "pyoma2_multisetup.py",
                                           "split_halves_pool.py", "block_scaling_mc.py",
                                           "above_order_diagnosis.py", "partial_unfreeze_mc.py",
                                           "bootstrap_sigma_mc.py", "coupling_sketch.py", "selected_members_mc.py",
                                           "diagram_shape_test.py", "regularized_gap_mc.py",
                                           "monitoring_shape_test.py", "selected_members_block_mc.py",
                                           "bootstrap_cv_mc.py"}
    assert scripts == tested


@pytest.mark.slow
def test_warnings_issue27(capsys, tmp_path):
    out = _module("warnings_issue27").main(tmp_path, n_seeds=1)  # no records in tmp_path: simulations only
    assert out["records"] == {} and set(out["simulations"]) == set(_module("warnings_issue27").SIMULATIONS)
    beam = out["simulations"]["beam-like OO, band 0.5-20 Hz"][0]
    assert beam["block_rows"] == 37 and "short_lags" not in beam["kinds"]
    assert "| simulation | runs | fired (runs) |" in capsys.readouterr().out


@pytest.mark.slow
def test_warnings_issue27_premise(capsys):
    study = _module("warnings_issue27_premise")
    assert study.main("chain", 200, seeds=range(2)).shape == (2, 4)
    assert study.main("mass-0.0005", 20, seeds=range(2)).shape[1] == 4
    assert "chain, 200 blocks of 1.98 s" in capsys.readouterr().out


@pytest.mark.slow
def test_selected_sigma_mc(capsys):
    out = _module("selected_sigma_mc").main(n_records=2, duration=40.0, bootstrap_draws=10)
    assert set(out) == {"input/output", "output-only", "input/output, cluster mean", "output-only, cluster mean"}
    assert out["output-only"].shape == (2, 6, 4)
    assert "| mode | f (Hz) | found |" in capsys.readouterr().out


def test_selected_members_block_mc(capsys, tmp_path):
    mod = _module("selected_members_block_mc")
    out = tmp_path / "frame.pkl"
    data = mod.run(3, "frame", out, duration=60.0)
    row = next(r for r in data["records"]["IO"][0] if "default" in r)
    assert {"default", "block corr", "block corr c_rep", "default rho_rep", "n_blocks"} <= set(row)
    assert row["default c_rep"] == 1.0  # the default identification does not correct
    mod.report([str(out)])
    text = capsys.readouterr().out
    assert "| block corr |" in text and "gate fired at the representative" in text


def test_selected_members_mc(capsys, tmp_path):
    mod = _module("selected_members_mc")
    out = tmp_path / "frame.pkl"
    data = mod.run(3, "frame", out, duration=60.0)
    assert set(data["records"]) == {"OO", "IO"} and len(data["records"]["OO"]) == 3
    row = next(r for r in data["records"]["OO"][0] if "default" in r)
    assert {"default", "no order check", "no pole reassign", "mean", "lowest", "members", "widened", "k_star",
            "n_selected"} <= set(row)
    assert len(row["members"]["order"]) == len(row["members"]["coupled"]) > 0
    mod.report([str(out)])
    text = capsys.readouterr().out
    assert "| no order check |" in text and "σ widened by the order" in text
    assert "| unanchored (ρ > 2): ρ σ |" in text
    assert "| interval ± t σ (t of n_blocks − 1) |" in text and row["n_blocks"] >= 2
    assert "true modes found / modes selected per record" in text and "no pole reassign [" in text
    # capped at 3 k*: no member of any selected mode above it
    capped = mod.run(2, "frame", duration=60.0, k_star_factor=3.0)
    rows = [r for recs in capped["records"].values() for rec in recs for r in rec if "members" in r]
    assert rows and all(r["members"]["order"].max() <= 3 * r["k_star"] for r in rows)
    # issue 27 (o): the fixed-order table bins every member pole by its rho, once
    bins = mod.fixed_order_by_rho(data["records"]["OO"], min_records=2)
    n_members = sum(len(r["members"]["order"]) for rec in data["records"]["OO"] for r in rec if "members" in r)
    assert bins and sum(b[0] for b in bins.values()) <= n_members
    assert all(0 <= b[3] <= 1 and 0 <= b[4] <= 1 and b[1] > 0 for b in bins.values())
    assert "member poles as fixed-order estimators by ρ" in text
    paired = mod.fixed_order_by_rho(data["records"]["OO"], paired=True)  # records 0 and 1 paired, 2 alone
    assert paired and "the same read as the split halves read them" in text
    assert sum(b[0] for b in paired.values()) == len(mod._paired_orders(data["records"]["OO"]))
    # the record variations: 2 blocks fewer than the automatic, AR(1) sensor noise
    varied = mod.run(1, "frame", duration=60.0, n_blocks=12, sensor_noise_ar=(0.9, 0.1))
    assert varied["records"]["OO"][0]
    sim = mod.modaluq.simulate(600, seed=1, noise_std=0.0)
    noisy = mod.with_ar_sensor_noise(sim, 5, 0.9, 0.1)
    assert np.allclose(np.std(noisy - sim.y, axis=0), 0.1 * sim.y.std(0))
    # the colored excitation: at phi = 0 it is simulate's record, sample for sample
    y, u, truth = mod.colored_chain(600, 3, 0.0)
    sim = mod.modaluq.simulate(600, seed=3)
    assert np.allclose(y, sim.y, rtol=0, atol=1e-12 * np.abs(sim.y).max()) and np.array_equal(u, sim.u)
    assert np.allclose(truth, np.sort(sim.frequency_hz))
    assert mod.run(1, "chain", duration=60.0, excitation_ar=0.7)["records"]["IO"][0]
    with pytest.raises(ValueError, match="excitation_ar"):
        mod.run(1, "frame", duration=60.0, excitation_ar=0.7)
    # modes outside the band: the 10-DOF chain's five modes in 1-10 Hz are its true modes
    c10 = mod.run(1, "chain10", duration=60.0)
    assert len(c10["truth"]) == 5 and c10["truth"].max() < 10 and len(c10["records"]["OO"][0]) == 5
    # issue 27 (p): the koma frame's system, output-only; its modes are the data README's reference
    # (koma's omega_n / 2 pi), its displacements largest at the top level (column 0)
    koma = mod.run(1, "koma", duration=120.0)
    assert set(koma["records"]) == {"OO"}
    assert koma["truth"] == pytest.approx([0.1812, 0.5289, 0.8338, 1.0711, 1.2217], abs=1e-4)
    y, _ = mod.koma_frame(1440, 1, noise=0.0)
    assert y.shape == (1440, 5) and np.all(np.diff(y.std(0)) < 0)
    with pytest.raises(ValueError, match="koma"):
        mod.run(1, "koma", duration=60.0, sensor_noise_ar=(0.9, 0.1))


@pytest.mark.slow
def test_indicators_mc(capsys):
    out = _module("indicators_mc").main(n_records=2, duration=60.0, representative="shape-lowest", structure="frame")
    assert len(out) == 4 and all(a.shape == (2, 4, 13) for a in out.values())  # the frame's 4 modes
    text = capsys.readouterr().out
    assert "same-mode rejected at 5 %" in text and "truth rejected at 5 %" in text and "engineer's call (representative 'shape-lowest')" in text


def test_automac_mc(capsys):
    out = _module("automac_mc").main(n_records=2, n_samples=6000)
    assert set(out) == {f"{kind}, {call}" for kind in ("output-only", "input/output")
                        for call in ("true order", "engineer's call", "engineer's call, lowest")}
    assert "| pair | MAC | σ_MC | approx. / σ_MC | exact / σ_MC |" in capsys.readouterr().out


def test_diagram_shape_test(capsys):
    rows = _module("diagram_shape_test").main(1, "frame", n_samples=6000)
    assert set(rows) == {"output-only", "input/output"}
    for x in rows.values():  # every matched pole: its order over k*, class, MAC flag and two p-values
        assert x.shape[1] == 5 and len(x) > 10 and set(np.unique(x[:, 1])) <= {0.0, 1.0}
    assert "| physical |" in capsys.readouterr().out


@pytest.mark.slow
def test_multisetup_mc(capsys):
    out = _module("multisetup_mc").main(n=2, configs=["output-only"])
    assert set(out) == {"output-only"} and len(out["output-only"]) == 2
    assert "| mode | f (Hz) | method |" in capsys.readouterr().out


@pytest.mark.slow
def test_io_block_bias(capsys):
    out = _module("io_block_bias").main(n_records=3, n_samples=4000, n_reference=20_000)
    assert out["est"]["columns"].shape == (3, 4, 12) and out["K"].shape == (12,)
    assert "| n_blocks | estimator | f: mean σ/σ_MC |" in capsys.readouterr().out


def test_block_scaling_mc(capsys, tmp_path):
    study = _module("block_scaling_mc")
    out = study.main(n_records=4, out=tmp_path / "run.npz", progress=False)
    assert set(out) == set(study.CASES)
    assert out["paper"]["f"].shape == (1, 2, 3, 4, 6) and out["known"]["f"].shape == (2, 2, 2, 4, 6)
    assert out["known-mid"]["f"].shape == (2, 1, 2, 4, 6) and out["light"]["rho_f"].shape == (2, 1, 2, 4, 6) and out["frame"]["sx"].shape == (1, 2, 3, 4, 4)
    assert np.isfinite(out["frame"]["rho_f"][0, 1, 0]).all()   # IO, true order: every mode matched
    text = capsys.readouterr().out
    assert "| n_b | method | order | σ | f: median σ/σ_MC |" in text and "| cells | estimator | n |" in text
    loaded, meta = study.load(tmp_path / "run.npz")
    assert meta["n_records"] == 4 and np.array_equal(loaded["paper"]["sf"], out["paper"]["sf"], equal_nan=True)
    # the factor: c = max(1/4, 1 + 2 (mean ρ + 1/n_b)); the gate leaves |ρ + 1/n_b| ≤ 2/√n_b alone
    assert np.allclose(study.scale_factor([0.1, -0.9], [0.3, -0.9], 50), [1 + 2 * 0.22, 0.25])
    assert np.allclose(study.scale_factor([0.1, 0.5], [0.1, 0.5], 100, gated=True), [1.0, 2.02])


def test_above_order_diagnosis(capsys, tmp_path):
    study = _module("above_order_diagnosis")
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # statistics of 3 records
        out = study.main(n_records=3, out=tmp_path / "diag.npz", progress=False)
    assert out["sig_core"].shape == (2, 2, 3, 6, 2) and out["f"].shape == (2, 2, 3, 6)
    ok = np.isfinite(out["sig_core"]) & ~out["flag"][..., None]
    assert ok.any() and np.allclose(out["sig_core"][ok], out["sig_blk"][ok], rtol=1e-8, atol=0)
    # the permuted commutation product equals the oracle's explicit one
    H = np.random.default_rng(1).standard_normal((6, 4))
    assert np.allclose(study.jacobian_gamma_h(H, 3, frozen_from=2), study.oracle.jacobian_Gamma_H(H, 3, frozen_from=2))
    assert "| method | order | mode | n | (a) σ_core | (b) σ_trueH |" in capsys.readouterr().out


def test_monitoring_shape_test(capsys):
    study = _module("monitoring_shape_test")
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        study.gate_or_alarm(n_records=23, damage_record=21, n_samples=5000)
        p, ratios = study.rate_without_change(n_records=23, n_samples=5000)
        full, diagonal = study.full_or_diagonal(n_records=3, n_samples=5000)
    assert p.size > 0 and len(ratios) > 0 and full.shape == diagonal.shape and full.size > 0
    out = capsys.readouterr().out
    assert "wrong pairs" in out and "| full |" in out


def test_regularized_gap_mc(capsys, tmp_path):
    study = _module("regularized_gap_mc")
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # statistics of 2 records
        worst = study.checks(n_records=1, structure="frame")
        out = study.main(n_records=2, structure="frame", out=tmp_path / "rg.npz", progress=False)
    # c = 0 is the oracle's plain map and the own freeze its frozen one; the true order barely moves
    assert worst[1] < 1e-9 and worst[2] < 1e-11 and worst[4] < 1e-2 and worst["core"] < 1e-9
    assert (tmp_path / "rg.npz").exists() and out is not None
    assert "| variant | order 8 | order 16 | order 24 |" in capsys.readouterr().out


def test_partial_unfreeze_mc(capsys, tmp_path):
    study = _module("partial_unfreeze_mc")
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # statistics of 2 records
        out = study.main(n_records=2, structure="frame", out=tmp_path / "pu.npz", progress=False)
    assert out["s_frozen"].shape == (2, 2, 2, 4, 2) and out["f"].shape == (2, 2, 2, 4)
    # κ = 0 is the frozen map, κ = 1 the plain one; at the true order (k* ≥ 8) they coincide
    a, b = out["s_frozen"], out["s_plain"]
    assert np.allclose(study.sigma_kappa(a, b, 0.0), a, equal_nan=True)
    assert np.allclose(study.sigma_kappa(a, b, 1.0), b, equal_nan=True)
    ok = np.isfinite(a[:, 0]) & (out["k_star"][:, :, None, None] >= 8)
    assert np.allclose(a[:, 0][ok], b[:, 0][ok], rtol=1e-12)
    assert "| method | order | mode | n | κ=0 |" in capsys.readouterr().out


def test_bootstrap_sigma_mc(capsys, tmp_path):
    study = _module("bootstrap_sigma_mc")
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # statistics of 2 records
        out = study.main(n_records=2, structure="frame", draws=12, out=tmp_path / "bs.npz", progress=False)
    assert out["s_boot"].shape == (2, 3, 2, 4, 2, 2) and out["k_star"].shape == (2, 2)
    assert "| hybrid |" in capsys.readouterr().out
    # with a vanishing perturbation the bootstrap is the plain first-order map on the same draws:
    # the std over the draws of j_plain T_H ε_b (output-only: H = R1, so T_H = T_R)
    from modaluq.simulate import simulate
    sim = simulate(study.N_SAMPLES, seed=5, n_dof=4, input_dofs=(0, 3))
    draws, seed = 40, 3
    bs = study.bootstrap(sim.y, None, sim.fs, (8,), draws=draws, scales=(1e-6,), seed=seed)[8]
    rec = study.record_maps(sim.y, None, sim.fs, (8,))
    eps = np.random.default_rng(seed).standard_normal((rec["T_H"].shape[1], draws))
    lin = np.std(rec[8]["plain"] @ rec["T_H"] @ eps, axis=-1, ddof=1)             # modes × 2
    assert np.allclose(bs["f"], rec[8]["f"], rtol=1e-12)
    assert np.allclose(bs["boot"][0], lin, rtol=1e-3)


def test_bootstrap_cv_mc(capsys, tmp_path):
    study = _module("bootstrap_cv_mc")
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # statistics of 2 records
        out = study.main(n_records=2, structure="frame", draws=12, out=tmp_path / "cv.npz", progress=False)
    assert out["s_cv"].shape == (2, 3, 2, 4, len(study.DRAW_COUNTS), 2)
    # the oracle's frozen first-order σ is the core's wherever the core kept it (poles not flagged)
    ok = np.isfinite(out["s_lin"]) & ~out["flag"][..., None]
    assert ok.sum() > 20 and np.allclose(out["s_lin"][ok], out["s_core"][ok], rtol=1e-6)
    # at the true order (8) the draws move the poles as the first-order map says
    assert np.nanmedian(out["corr"][:, 0]) > 0.95
    assert "| cv100 all |" in capsys.readouterr().out


def test_poser_mc(capsys):
    out = _module("poser_mc").main(n=3, configs=["output-only"])
    assert set(out) == {"output-only"} and len(out["output-only"]) == 3
    out = _module("poser_mc").main(n=2, configs=["diagram", "input/output"])
    assert set(out) == {"input/output"} and out["input/output"][0]["poser"].shape == (6, 4)  # f, σ_f, ξ, σ_ξ
    assert out["input/output"][0]["modular shape"].shape[:2] == (6, 3)  # shape, σ Re, σ Im per true mode
    text = capsys.readouterr().out
    assert "| mode | f (Hz) | method |" in text and "MC std f modular/PoSER" in text
    assert "frozen merge" in text and "coverage f modular / PoSER" in text
    assert "| mode | σ_f/MC mean / median |" in text  # the modular σ of the cluster's mean beside the median
    assert out["input/output"][0]["modular median"].shape == (6, 4)
    out = _module("poser_mc").main(n=2, configs=["diagram", "auto", "output-only"])  # frequency_range only
    assert "poser" not in out["output-only"][0] and out["output-only"][0]["modular"].shape == (6, 4)
    assert "frequency_range (0.5, 11) Hz only" in capsys.readouterr().out


def test_coupling_sketch(capsys):
    rows = _module("coupling_sketch").main(["1", "--setups", "3", "--samples", "20000", "--sketch", "4"])
    r = rows[4]
    flagged = r["both"] + r["exact_only"] + r["sketch_only"] + r["neither"]
    assert flagged == len(r["log_rho"]) > 0 and r["same_selection"] in (0, 1)
    assert "| s | merge CPU s | flagged both" in capsys.readouterr().out


def test_pyoma2_multisetup(capsys, monkeypatch):
    # modaluq's side only (pyOMA2 is not a test dependency: without it the peer's columns are left out)
    monkeypatch.delenv("PYOMA2_PYTHON", raising=False)
    study = _module("pyoma2_multisetup")
    monkeypatch.setattr(study, "_has_pyoma2", lambda: False)
    out = study.main(n_seeds=2)
    assert out["pyoma2"] is None and ("modaluq modular", 12) in out["rows"]
    assert "| mode | true f (Hz) |" in capsys.readouterr().out


def test_settings_records_without_data(capsys, tmp_path):
    study = _module("settings_records")
    with pytest.raises(ValueError, match="record 'nothing'"):
        study.main(tmp_path, records=["nothing"])
    assert "| record | decimation |" in capsys.readouterr().out


@needs_data
@pytest.mark.slow
def test_settings_records(capsys):
    _module("settings_records").main(DATA, records=("koma", "slab"))
    lines = capsys.readouterr().out.splitlines()
    assert lines[2].startswith("| koma frame") and lines[3].startswith("| slab")


@needs_data
@pytest.mark.slow
def test_earthquake_records(capsys):
    out = _module("earthquake_records").main(DATA, records=("Meloland",), kinds=("default",))
    targets, results = out["Meloland"]
    assert {t["verdict"] for t in targets} <= {"physical", "probable", "not shown", "not found"}
    assert set(results) == {"default OO", "default IO"}
    assert "Meloland" in capsys.readouterr().out


def test_split_halves_pool_without_data(tmp_path):
    with pytest.raises(ValueError, match="record 'nothing'"):
        _module("split_halves_pool").main(tmp_path, records=["nothing"])


@needs_data
def test_split_halves_pool(capsys, tmp_path):
    rows, failed = _module("split_halves_pool").main(DATA, tmp_path / "pairs.csv", records=("sensor array",),
                                                     levels=(1,))
    assert failed == [] and {r["record"] for r in rows} <= {"sensor array"}
    assert (tmp_path / "pairs.csv").read_text().startswith("group,record,n_windows,window")
    assert "| **measured, pooled** |" in capsys.readouterr().out


@needs_data
def test_split_halves_pool_fixed_orders(capsys):
    pairs, orders = _module("split_halves_pool").main(DATA, records=("sensor array",), levels=(1,), fixed_orders=True)
    assert pairs and all(p["record"] == "sensor array" and p["common_orders"] >= 1 for p in pairs)
    assert len(orders) == sum(p["common_orders"] for p in pairs)
    # the selected modes' z are those of split_halves on the same halves (the default pool)
    rows, _ = _module("split_halves_pool").main(DATA, records=("sensor array",), levels=(1,))
    assert sorted(p["z_f"] for p in pairs) == pytest.approx(sorted(r["z_f"] for r in rows))
    assert all(-1 <= p["row_correlation0"] <= 1 and -1 <= p["lag1_xi0"] <= 1 for p in pairs)
    out = capsys.readouterr().out
    assert "| sensor array | 1 |" in out and "ρ₁ ξ" in out and "| ρ 0–1.2 | ρ 1.2–2 | ρ 2–5 | ρ 5–inf |" in out
    assert "each half's pole read with its own σ" in out
    assert all(len(o["own"]) == 2 for o in orders)


def test_split_halves_pool_on_simulated_koma_records(capsys):
    mod = _module("split_halves_pool")
    names = mod.simulated_koma(1)
    rows, failed = mod.main("unused", records=names, levels=(1,))
    assert rows and not failed and {r["group"] for r in rows} == {"Monte Carlo"}
    r = rows[0]
    assert r["z_f_own1"] == pytest.approx((r["f1_hz"] - r["f2_hz"]) / np.sqrt(2) / r["sigma_f1_hz"])
    out = capsys.readouterr().out
    assert "| **Monte Carlo, pooled** |" in out and "measured, pooled" not in out and "each half's own σ" in out


# every script of studies/high_orders with the arguments of a tiny run, in the order of
# docs/validation-high-orders.md "Reproducing": the runs write the npz files the reports read
# (one or two records each, a short reference for hcov.py; the file names are those the reports expect)
HIGH_ORDER_RUNS = {
    "check.py": (),
    "fdcheck.py": (),
    "look.py": (),
    "mc.py": (1, "mc_300.npz"),
    "mc2.py": (1, "mc2_300.npz"),
    "mc3.py": (1, "mc3_300.npz"),
    "mc4.py": (1, "mc4_300.npz"),
    "mc5.py": (1, "mc5_300.npz"),
    "boot.py": (1, 2, "boot150.npz"),
    "hcov.py": (2, "hcov_io.npz", 0.1, 40_000),
    "nbscan.py": (1, "nbscan.npz"),
    "spurious.py": (1,),
    "flag_spurious.py": (1,),
    "wtest.py": (1,),
    "flag_records.py": (2, "frozen.npy", 0.1, 50, 0.02, 1e300, 1),
    "analyze.py": ("mc2_300.npz", "base", "d3"),
    "calib.py": ("mc3_300.npz",),
    "compact.py": ("mc3_300.npz",),
    "flagcalib.py": ("mc5_300.npz", "w1.5", 5),
    "flagcheck.py": ("mc5_300.npz", "w1.5"),
    "zscore.py": ("mc2_300.npz",),
    "xi_outliers.py": ("mc5_300.npz", "w1.5"),
    "boot_report.py": ("boot150.npz",),
    "hcov_report.py": ("hcov_io.npz",),
    "final_checks.py": (),
    "flag_threshold.py": ("frozen.npy", "frozen.npy", "5,10,20"),
    "tables.py": (),
    "build_doc.py": ("validation-high-orders.md",),
    "issue11_records.py": (DATA,),
    "issue11_tables.py": ("mc",),
    "issue11_figure.py": ("mc", "figure.png"),
}


@pytest.mark.slow
def test_high_orders(monkeypatch, tmp_path, capsys):
    monkeypatch.chdir(tmp_path)
    monkeypatch.syspath_prepend(str(HIGH_ORDERS))  # the scripts import prop.py beside them
    monkeypatch.setenv("PYTHONPATH", os.pathsep.join(sys.path))  # build_doc.py runs the reports in subprocesses
    from modaluq.validation import monte_carlo

    # what validate_runs.sh writes (the CLI's files), for issue11_tables.py and issue11_figure.py
    for case, freeze in (("chain", True), ("chain-plain", False)):
        (tmp_path / "mc" / case).mkdir(parents=True)
        for r in monte_carlo(3, order=(12, 18, 24, 36), processes=1, progress=False, n_bootstrap=0,
                             freeze_noise=freeze):
            r.save(tmp_path / "mc" / case / f"results_n{r.settings['order']}.npz")
    for name, args in HIGH_ORDER_RUNS.items():
        if name == "hcov_report.py":  # tables.py reads a run without unknown forces too
            shutil.copy(tmp_path / "hcov_io.npz", tmp_path / "hcov_io0.npz")
        if name == "issue11_records.py" and not DATA.exists():
            continue
        _script(monkeypatch, name, *args)
    assert "{{" not in (tmp_path / "validation-high-orders.md").read_text()
    assert (tmp_path / "figure.png").stat().st_size > 0
    assert np.load(tmp_path / "frozen.npy").shape == (2, 4, 2, 6, 6)
    capsys.readouterr()
