#!/usr/bin/env python
"""What the bootstrap of σ above the noise floor costs (issue 27; docs/uq-math.md §5.6).

    python bench/bootstrap.py                  # U1, U2, IO of bench/run.py and the engineer's call
    python bench/bootstrap.py --repeats 5 --draws 50 100

Each case is identified with ``bootstrap_draws`` = 0 (the default) and each value of ``--draws``,
in one process, one BLAS thread, ``threads=1``, the variants interleaved in every repeat; CPU
seconds (time.process_time) around ``modaluq.identify``, the best of the repeats, and the ratio
to ``bootstrap_draws=0`` of the same run. The cases: bench/run.py's U1 (6-DOF chain, 3 outputs,
10⁵ samples, p = 40, orders 2..100), U2 (30-DOF chain, 20 outputs, p = 20, orders 2..100), IO (U1
input/output), and "auto": the paper's chain, 400 s at 50 Hz, ``frequency_range=(1, 20)`` (the
automatic settings an engineer gets).
"""

from __future__ import annotations

import os

for _v in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS", "BLIS_NUM_THREADS"):
    os.environ[_v] = "1"

import argparse  # noqa: E402
import sys  # noqa: E402
import time  # noqa: E402
import warnings  # noqa: E402

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, HERE)
from run import CONFIGS, SEED, _orders  # noqa: E402  (bench/run.py's configurations)


def cases():
    import modaluq

    out = {}
    for name in ("U1", "U2", "IO"):
        cfg = CONFIGS[name]
        sim = modaluq.simulate(cfg["n"], seed=SEED, n_dof=cfg["n_dof"])
        kw = dict(fs=sim.fs, block_rows=cfg["p"], orders=_orders(cfg), n_blocks=cfg["n_blocks"])
        out[name] = (sim.y, sim.u if cfg["io"] else None, kw)
    sim = modaluq.simulate(20_000, seed=SEED)
    out["auto"] = (sim.y, None, dict(fs=sim.fs, frequency_range=(1, 20)))
    return out


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--draws", type=int, nargs="+", default=[50, 100])
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--only", default=None, help="comma list of cases (U1, U2, IO, auto)")
    args = ap.parse_args(argv)
    import modaluq

    variants = [0] + list(args.draws)
    rows = []
    for name, (y, u, kw) in cases().items():
        if args.only and name not in args.only.split(","):
            continue
        best = {b: float("inf") for b in variants}
        info = ""
        for _ in range(args.repeats):
            for b in variants:
                with warnings.catch_warnings():
                    warnings.simplefilter("ignore")
                    t0 = time.process_time()
                    res = modaluq.identify(y, u, bootstrap_draws=b, **kw)
                    best[b] = min(best[b], time.process_time() - t0)
                if b:
                    above = sum(int(m.bootstrapped.sum()) for m in res.modes if m.bootstrapped is not None)
                    info = (f"k* = {res.significant_singular_values}, orders {res.settings['orders'][0]}.."
                            f"{res.settings['orders'][-1]}, p = {res.settings['block_rows']}, "
                            f"{above} poles bootstrapped")
        rows.append((name, info, best))
        print(f"{name}: {info}", file=sys.stderr, flush=True)
    print(f"modaluq {modaluq.__version__}, core path {modaluq._core.cpu_path}, one thread, best of {args.repeats}\n")
    print("| case | what | " + " | ".join(f"B = {b} (CPU s)" for b in variants) + " | "
          + " | ".join(f"ratio B = {b}" for b in args.draws) + " |")
    print("|---|---|" + "---|" * (2 * len(variants) - 1))
    for name, info, best in rows:
        print(f"| {name} | {info} | " + " | ".join(f"{best[b]:.3f}" for b in variants) + " | "
              + " | ".join(f"{best[b] / best[0]:.2f}" for b in args.draws) + " |")


if __name__ == "__main__":
    main()
