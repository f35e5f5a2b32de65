"""Reproduce GeVI-SLAM Fig. 4a-b (spec 11.3): yaw / translation RMSE vs number of points.

Estimators: LS, BE ("ours w/o GN"), BE+GN ("ours"), BE+GN with 0.01 deg roll/pitch noise, BE+GN
with the BE covariance (``pnp4_gn(..., be_cov=...)``: BE kept where cost (1) is less informative),
6-DOF Bias-Eli-W + one weighted step, OpenCV EPnP and SQPnP (on the triangulated points,
identity K, normalized coordinates); CRLB4 (root-mean rule of spec 11.1).

    python scripts/fig4_consistency.py [--quick] [--runs 700] [--out DIR]
"""

from __future__ import annotations

import argparse
import os
import time

import matplotlib

matplotlib.use("Agg")
import cv2  # noqa: E402
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
import pandas as pd  # noqa: E402

from gevi_cli.estimators import EstimatorError, pnp4_gn, pnp6_be, pnp6_refine  # noqa: E402
from gevi_cli.estimators.pnp4 import pnp4_be_cov  # noqa: E402
from gevi_cli.geometry import wrap_angle  # noqa: E402
from gevi_cli.studies import montecarlo as mc  # noqa: E402
from gevi_cli.studies.outlier_study import yaw_of  # noqa: E402

NS = [3, 5, 10, 20, 50, 100, 200, 500, 1000]
NAN = (np.nan, np.full(3, np.nan))


def baselines(s, p, cov, out):
    def rec(name, R, t):
        out[name] = (float(wrap_angle(yaw_of(R, s.L_k, s.L_c) - s.psi)), t - s.t)

    try:  # BE + GN with the BE covariance: BE kept along directions where cost (1) is weaker
        psi, t, C = pnp4_be_cov(p, cov, s.q, s.L_k, s.L_c)
        psi, t = pnp4_gn(psi, t, s.z, s.y, s.q, s.L_k, s.L_c, s.R_rl, s.t_rl, be_cov=C, sigma2=s.sigma**2)
        out["gn_becov"] = (float(wrap_angle(psi - s.psi)), t - s.t)
    except (EstimatorError, np.linalg.LinAlgError):
        out["gn_becov"] = NAN

    try:
        R, t = pnp6_be(p, cov, s.q)
        rec("bias_eli_w_refine", *pnp6_refine(R, t, p, cov, s.q))
    except EstimatorError:
        out["bias_eli_w_refine"] = NAN
    for name, flag, nmin in (("epnp", cv2.SOLVEPNP_EPNP, 4), ("sqpnp", cv2.SOLVEPNP_SQPNP, 3)):
        if len(p) < nmin:
            out[name] = NAN
            continue
        ok, rv, tv = cv2.solvePnP(p.reshape(-1, 1, 3), s.q.reshape(-1, 1, 2), np.eye(3), None, flags=flag)
        if not ok:
            out[name] = NAN
            continue
        rec(name, cv2.Rodrigues(rv)[0], tv.ravel())


LABELS = {
    "ls": "LS",
    "be": "Ours w/o GN (BE)",
    "gn": "Ours (BE+GN)",
    "gn_noisy_rp": "Ours (noisy roll/pitch 0.01°)",
    "gn_becov": "Ours, BE-informed weak directions",
    "bias_eli_w_refine": "Bias-Eli-W + refine (6-DOF)",
    "epnp": "EPnP (OpenCV)",
    "sqpnp": "SQPnP (OpenCV)",
}


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--runs", type=int, default=700)
    ap.add_argument("--quick", action="store_true", help="100 runs, n up to 500")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--out", default=os.path.join(os.path.dirname(__file__), "results", "fig4_consistency"))
    ap.add_argument("--update-docs", action="store_true", help="also copy the PNG to docs/img/ (README figure)")
    a = ap.parse_args()
    runs = 100 if a.quick else a.runs
    ns = NS[:-1] if a.quick else NS
    os.makedirs(a.out, exist_ok=True)
    rows = []
    t0 = time.time()
    for n in ns:
        r = mc.run4(n, runs, seed=a.seed + n, noisy_rp_deg=0.01, extra=baselines, nan_on_failure=True)
        for k in LABELS:
            rows.append(dict(n=n, estimator=k, runs=runs, failures=r.failures(k),
                             yaw_rmse_deg=np.degrees(r.rmse_yaw(k)), t_rmse_cm=100 * r.rmse_t(k),
                             t_bias_cm=100 * float(np.linalg.norm(np.nanmean(r.t[k], axis=0))),
                             t_se_cm=100 * r.rmse_t(k) / np.sqrt(runs)))
        rows.append(dict(n=n, estimator="crlb4", runs=runs, failures=0, yaw_rmse_deg=np.degrees(r.bound_yaw()),
                         t_rmse_cm=100 * r.bound_t(), t_bias_cm=np.nan, t_se_cm=np.nan))
        print(f"n={n:5d} done ({time.time() - t0:.0f} s)", flush=True)
    df = pd.DataFrame(rows)
    df.to_csv(os.path.join(a.out, "fig4_consistency.csv"), index=False)

    pd.set_option("display.width", 200)
    piv = df.pivot(index="n", columns="estimator", values="yaw_rmse_deg")
    print("\nyaw RMSE [deg]\n", piv.round(4).to_string())
    print("\ntranslation RMSE [cm]\n", df.pivot(index="n", columns="estimator", values="t_rmse_cm").round(3).to_string())
    print("\ntranslation |bias| [cm] (SE per axis in t_se_cm)\n",
          df.pivot(index="n", columns="estimator", values="t_bias_cm").round(3).to_string())
    gn = df[df.estimator == "gn"].set_index("n")
    cr = df[df.estimator == "crlb4"].set_index("n")
    big = [n for n in ns if n >= 50]
    print("\nBE+GN log-log slope (n >= 50): yaw %.3f  t %.3f" % (
        mc.loglog_slope(big, gn.loc[big, "yaw_rmse_deg"]), mc.loglog_slope(big, gn.loc[big, "t_rmse_cm"])))
    gb = df[df.estimator == "gn_becov"].set_index("n")
    print("RMSE / root-mean CRLB4 ratio (BE+GN; BE+GN with be_cov):\n",
          pd.DataFrame({"yaw": gn.yaw_rmse_deg / cr.yaw_rmse_deg, "t": gn.t_rmse_cm / cr.t_rmse_cm,
                        "yaw_becov": gb.yaw_rmse_deg / cr.yaw_rmse_deg,
                        "t_becov": gb.t_rmse_cm / cr.t_rmse_cm}).round(3).to_string())

    fig, ax = plt.subplots(1, 2, figsize=(11, 4.2))
    style = {"crlb4": dict(color="k", ls="--", marker="")}
    for k in list(LABELS) + ["crlb4"]:
        d = df[df.estimator == k]
        for j, col in enumerate(("yaw_rmse_deg", "t_rmse_cm")):
            kw = dict(marker="o", ms=3)
            kw.update(style.get(k, {}))
            ax[j].loglog(d.n, d[col], label=LABELS.get(k, "CRLB$_4$"), **kw)
    ax[0].set_ylabel("yaw RMSE [deg]")
    ax[1].set_ylabel("translation RMSE [cm]")
    for x in ax:
        x.set_xlabel("number of points n")
        x.grid(True, which="both", alpha=0.3)
    ax[1].legend(fontsize=7)
    fig.suptitle(f"GeVI Fig. 4a-b reproduction ({runs} runs per n, 2.5 px, b = 0.2 m)")
    fig.tight_layout()
    fig.savefig(os.path.join(a.out, "fig4_consistency.png"), dpi=80)
    if a.update_docs and not a.quick and a.runs >= 700:
        import shutil

        dst = os.path.join(os.path.dirname(__file__), "..", "docs", "img", "fig4_consistency.png")
        shutil.copyfile(os.path.join(a.out, "fig4_consistency.png"), dst)
        print("copied the PNG to", dst)
    print("wrote", a.out)


if __name__ == "__main__":
    main()
