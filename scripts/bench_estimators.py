"""Microbenchmark of the estimators: microseconds per call at n = 50 / 200 / 1000.

Target (issue 3): 4-DOF BE+GN and Bias-Eli-W + refine each under 1 ms at n = 200.

    python scripts/bench_estimators.py [--repeat 200] [--out DIR]
"""

from __future__ import annotations

import argparse
import os
import timeit

import numpy as np
import pandas as pd

from gevi_cli import estimators as est
from gevi_cli.estimators.pnp4 import pnp4_be_cov
from gevi_cli.studies import simulation as sim


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--repeat", type=int, default=200)
    ap.add_argument("--out", default=os.path.join(os.path.dirname(__file__), "results", "bench_estimators"))
    a = ap.parse_args()
    os.makedirs(a.out, exist_ok=True)
    rows = []
    for n in (50, 200, 1000):
        rng = np.random.default_rng(n)
        s = sim.scene4(rng, n)
        p, cov = est.triangulate(s.z, s.y, s.R_rl, s.t_rl, s.sigma**2)
        be4 = est.pnp4_be(p, cov, s.q, s.L_k, s.L_c)
        R6, t6 = est.pnp6_be(p, cov, s.q)
        qo, _ = sim.add_outliers(rng, s.q, 0.3)

        def be4c(p=p, cov=cov, s=s):
            psi, t, be4c.C = pnp4_be_cov(p, cov, s.q, s.L_k, s.L_c)
            return psi, t

        cases = {
            "sigma2_onesided": lambda: est.sigma2_onesided(s.q, s.z),
            "sigma2_stereo": lambda: est.sigma2_stereo(s.z, s.y, s.R_rl, s.t_rl),
            "triangulate (+cov)": lambda: est.triangulate(s.z, s.y, s.R_rl, s.t_rl, s.sigma**2),
            "pnp6_ls": lambda: est.pnp6_ls(p, s.q),
            "pnp6_be": lambda: est.pnp6_be(p, cov, s.q),
            "pnp6_refine": lambda: est.pnp6_refine(R6, t6, p, cov, s.q),
            "pnp6_be + refine": lambda: est.pnp6_refine(*est.pnp6_be(p, cov, s.q), p, cov, s.q),
            "pnp_l1_filter": lambda: est.pnp_l1_filter(p, s.q),
            "pnp4_ls": lambda: est.pnp4_ls(p, s.q, s.L_k, s.L_c),
            "pnp4_be": lambda: est.pnp4_be(p, cov, s.q, s.L_k, s.L_c),
            "pnp4_gn": lambda: est.pnp4_gn(*be4, s.z, s.y, s.q, s.L_k, s.L_c, s.R_rl, s.t_rl),
            "pnp4_be + gn": lambda: est.pnp4_gn(*est.pnp4_be(p, cov, s.q, s.L_k, s.L_c), s.z, s.y, s.q, s.L_k,
                                                s.L_c, s.R_rl, s.t_rl),
            "pnp4_be_cov + gn(be_cov)": lambda: est.pnp4_gn(*be4c(), s.z, s.y, s.q, s.L_k, s.L_c, s.R_rl, s.t_rl,
                                                           be_cov=be4c.C, sigma2=s.sigma**2),
            "solve_3pt_upright": lambda: est.solve_3pt_upright(s.z[:3], s.q[:3], s.L_k, s.L_c),
            "ransac_3pt (30% outl.)": lambda: est.ransac_3pt_upright(s.z, qo, s.L_k, s.L_c, 3 * s.sigma, seed=1),
            "crlb4": lambda: est.crlb4(s.psi, s.t, s.z_o, s.y_o, s.q_o, s.L_k, s.L_c, s.R_rl, s.t_rl, s.sigma**2),
        }
        for name, fn in cases.items():
            rep = max(5, a.repeat // 20) if name == "pnp_l1_filter" else a.repeat
            fn()
            best = min(timeit.repeat(fn, number=1, repeat=rep))
            med = np.median(timeit.repeat(fn, number=1, repeat=rep))
            rows.append(dict(estimator=name, n=n, us_median=1e6 * med, us_best=1e6 * best))
    df = pd.DataFrame(rows)
    df.to_csv(os.path.join(a.out, "bench_estimators.csv"), index=False)
    tab = df.pivot(index="estimator", columns="n", values="us_median").reindex(list(cases))
    print("median microseconds per call (one core, shared machine)")
    print(tab.round(0).to_string())
    for k in ("pnp4_be + gn", "pnp6_be + refine"):
        v = tab.loc[k, 200]
        print(f"{k} at n=200: {v:.0f} us -> {'MET' if v < 1000 else 'NOT MET'} (< 1000 us)")


if __name__ == "__main__":
    main()
