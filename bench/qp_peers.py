#!/usr/bin/env python3
"""Our QP solver against the solvers of its own family on the MPC's QP corpus.

Peers (dense, as ours):
  * DAQP (dual active set, the method ours follows), on two forms:
      - "native": the 32 inputs, their bounds as DAQP's simple bounds, the MPC rows
        with DAQP's own soft constraints (sense bit 8) and per-row weights
        rho_l = rho_u = 1/rho_i, so DAQP solves exactly our problem
        min 1/2 x'Hx + f'x + sum 1/2 rho_i s_i^2 (its penalty is s^2 / (2 rho));
      - "slack": the standard form with explicit slack variables (80-106 variables),
        all variable bounds (s >= 0 included) as simple bounds.
    Cold: no active constraint given. Warm, native form: the working set our solve
    started from (the corpus's `warm_start`: the MPC's previous working set with its
    rows renumbered for this QP) marked active in `sense` (bit 1, bit 2 for a lower
    side), the same warm start ours gets; slack form (other indices): the constraints
    active at DAQP's own solution of the previous QP in file order.
    Time: DAQP's own figures, setup_time (workspace, Cholesky factor of H, the rows
    times R^-1, i.e. what our solve() also does) + solve_time (the iterations).
    "solve only" columns give solve_time alone.
  * proxsuite's dense ProxQP (augmented Lagrangian), on the standard form with
    explicit slacks, the variable bounds as its box constraints, eps_abs = 1e-9,
    eps_rel = 0, max_iter 1000. Time: its own setup_time + solve_time
    (compute_timings). Cold only: its warm start from the previous QP's (x, y, z) did
    not return within minutes on this corpus (proxsuite 0.8.0). Its times are
    milliseconds, so --proxsuite-reps defaults to 1.

Ours: the `solve_us_cold` / `solve_us_warm` keys of the corpus, written by
`host-sim qp-corpus --time` (median of its repetitions; solve() alone: input checks,
inversion of the factor R the MPC hands in, rows times R^-1, iterations, output).
With --record the script runs that command first, so both are measured in one run.

Each peer's time per QP is the median of --reps repetitions (each from the same
start). Percentiles are nearest-rank, as host-sim's. Accuracy: every peer's inputs
and native objective (slack penalties included, slack = violation) are compared with
ours; the stated tolerance is |J - J_ours| <= 1e-6 (1 + |J_ours|).

Usage:
  python3 -m venv /tmp/qpvenv && /tmp/qpvenv/bin/pip install -r bench/requirements.txt
  /tmp/qpvenv/bin/python bench/qp_peers.py --record --corpus out/qp
"""

import argparse
import glob
import json
import math
import os
import platform
import subprocess
import sys

import numpy as np

OBJ_TOL = 1e-6
DAQP_ACTIVE, DAQP_LOWER, DAQP_EQ, DAQP_SOFT = 1, 2, 5, 8
BOX_INF = 1e20


def percentile(values, q):
    """Nearest-rank percentile (host-sim's cost_model::percentile)."""
    s = sorted(values)
    if not s:
        return float("nan")
    return s[max(math.ceil(len(s) * q) - 1, 0)]


def opt(v, inf):
    return inf if v is None else v


class Qp:
    """One corpus QP in our native form, plus what the forms below need."""

    def __init__(self, entry):
        q = entry["native"]
        n, m = q["n"], q["m"]
        h = np.array(q["H"], dtype=float).reshape(n, n)
        if q.get("H_is_factor", False):
            r = np.triu(h)
            self.H = r.T @ r
        else:
            u = np.triu(h)
            self.H = u + u.T - np.diag(np.diag(u))
        self.f = np.array(q["f"], dtype=float)
        self.A = np.array(q["A"], dtype=float).reshape(m, n) if m else np.zeros((0, n))
        self.lo = np.array([opt(v, -np.inf) for v in q["lo"]])
        self.hi = np.array([opt(v, np.inf) for v in q["hi"]])
        self.x_lo = np.array([opt(v, -np.inf) for v in q["x_lo"]])
        self.x_hi = np.array([opt(v, np.inf) for v in q["x_hi"]])
        self.soft = np.array(q["soft"], dtype=float)
        self.n, self.m = n, m
        self.x_ours = np.array(entry["x"][:n])
        self.obj_ours = self.objective(self.x_ours)
        self.cold_us = entry.get("solve_us_cold")
        self.warm_us = entry.get("solve_us_warm")
        self.iters_ours = entry["iterations"]
        # Our warm start: (index in DAQP's native order, lower side?).
        self.warm_start = [
            (w["bound"] if "bound" in w else n + w["row"], w["side"] == "lower")
            for w in entry.get("warm_start", [])
        ]

    def objective(self, x):
        """Native objective, the slack of a soft row being its violation."""
        v = self.A @ x
        s = np.maximum(np.maximum(self.lo - v, v - self.hi), 0.0)
        s[self.soft <= 0] = 0.0
        return 0.5 * x @ self.H @ x + self.f @ x + 0.5 * np.sum(self.soft * s * s)

    # ---- DAQP, native soft rows ----
    def daqp_native(self):
        n = self.n
        bu = np.concatenate([self.x_hi, self.hi])
        bl = np.concatenate([self.x_lo, self.lo])
        sense = np.zeros(n + self.m, dtype=np.intc)
        is_soft = self.soft > 0
        sense[n:][is_soft] = DAQP_SOFT
        sense[n:][(~is_soft) & (self.lo == self.hi)] = DAQP_EQ
        sense[:n][self.x_lo == self.x_hi] = DAQP_EQ
        rho = np.zeros(n + self.m)
        rho[n:][is_soft] = 1.0 / self.soft[is_soft]
        return self.H, self.f, self.A, bu, bl, sense, rho

    # ---- standard form with explicit slacks ----
    def standard(self):
        """Variables [x; s] (one slack per soft row), box bounds, general rows."""
        n = self.n
        soft_rows = np.nonzero(self.soft > 0)[0]
        ns = len(soft_rows)
        nz = n + ns
        H = np.zeros((nz, nz))
        H[:n, :n] = self.H
        H[n:, n:] = np.diag(self.soft[soft_rows])
        f = np.concatenate([self.f, np.zeros(ns)])
        rows, lo, hi = [], [], []
        slack_of = {int(i): k for k, i in enumerate(soft_rows)}
        for i in range(self.m):
            a = np.zeros(nz)
            a[:n] = self.A[i]
            k = slack_of.get(i)
            if k is None:
                rows.append(a)
                lo.append(self.lo[i])
                hi.append(self.hi[i])
                continue
            if np.isfinite(self.lo[i]):
                r = a.copy()
                r[n + k] = 1.0
                rows.append(r)
                lo.append(self.lo[i])
                hi.append(np.inf)
            if np.isfinite(self.hi[i]):
                r = a.copy()
                r[n + k] = -1.0
                rows.append(r)
                lo.append(-np.inf)
                hi.append(self.hi[i])
        A = np.array(rows) if rows else np.zeros((0, nz))
        x_lo = np.concatenate([self.x_lo, np.zeros(ns)])
        x_hi = np.concatenate([self.x_hi, np.full(ns, np.inf)])
        return H, f, A, np.array(lo), np.array(hi), x_lo, x_hi


def median(v):
    return float(np.median(np.array(v)))


def warm_sense(sense, lam):
    """`sense` with the constraints active at `lam` marked active (DAQP's convention:
    lambda < 0 at a lower side)."""
    s = sense.copy()
    if lam is None or len(lam) != len(s):
        return s
    act = np.nonzero(lam != 0.0)[0]
    s[act] |= DAQP_ACTIVE
    s[act[lam[act] < 0]] |= DAQP_LOWER
    return s


def run_daqp(qps, form, reps):
    """DAQP on `form` ("native" or "slack"), cold and warm. Returns a dict of lists."""
    import daqp

    out = {k: [] for k in ("cold", "warm", "cold_solve", "warm_solve", "x", "it_cold",
                           "it_warm", "flag")}
    prev_lam = None
    prev_size = None
    for q in qps:
        if form == "native":
            H, f, A, bu, bl, sense, rho = q.daqp_native()
        else:
            H, f, A, lo, hi, x_lo, x_hi = q.standard()
            bu = np.concatenate([x_hi, hi])
            bl = np.concatenate([x_lo, lo])
            sense = np.zeros(len(bu), dtype=np.intc)
            sense[bl == bu] = DAQP_EQ
            rho = None
        size = len(sense)
        if form == "native":
            warm = sense.copy()
            for i, lower in q.warm_start:
                warm[i] |= DAQP_ACTIVE | (DAQP_LOWER if lower else 0)
        else:
            warm = warm_sense(sense, prev_lam if prev_size == size else None)
        res = {}
        for mode, s in (("cold", sense), ("warm", warm)):
            tot, sol = [], []
            for _ in range(reps):
                model = daqp.Model()
                flag, setup_s = model.setup(H, f, A, bu, bl, s)
                if rho is not None:
                    model.soft_weights(rho_l=rho, rho_u=rho)
                x, _fval, flag, info = model.solve()
                tot.append((setup_s + info["solve_time"]) * 1e6)
                sol.append(info["solve_time"] * 1e6)
            out[mode].append(median(tot))
            out[mode + "_solve"].append(median(sol))
            out["it_" + mode].append(info["iterations"])
            res[mode] = (x, info, flag)
        x, info, flag = res["warm"]
        out["x"].append(np.array(x[: q.n]))
        out["flag"].append(flag)
        prev_lam = np.array(info["lam"])
        prev_size = size
    return out


def run_proxsuite(qps, reps):
    """proxsuite dense, cold only: its warm start (WARM_START with the previous QP's
    x, y, z) did not return within minutes on this corpus (proxsuite 0.8.0)."""
    import proxsuite

    px = proxsuite.proxqp
    out = {k: [] for k in ("cold", "x", "it_cold", "flag")}
    clip = lambda v: np.clip(v, -BOX_INF, BOX_INF)  # noqa: E731
    for q in qps:
        H, f, A, lo, hi, x_lo, x_hi = q.standard()
        nz, n_in = H.shape[0], A.shape[0]
        ts = []
        for _ in range(reps):
            qp = px.dense.QP(nz, 0, n_in, True)
            qp.settings.eps_abs = 1e-9
            qp.settings.eps_rel = 0.0
            qp.settings.compute_timings = True
            qp.settings.verbose = False
            qp.settings.max_iter = 1000
            qp.settings.initial_guess = px.InitialGuess.NO_INITIAL_GUESS
            qp.init(H, f, None, None, A, clip(lo), clip(hi), clip(x_lo), clip(x_hi))
            qp.solve()
            info = qp.results.info
            ts.append(info.setup_time + info.solve_time)
        out["cold"].append(median(ts))
        out["it_cold"].append(info.iter)
        out["x"].append(np.array(qp.results.x[: q.n]))
        out["flag"].append(str(info.status))
    return out


def accuracy(qps, xs):
    dx = max(float(np.max(np.abs(x - q.x_ours))) for q, x in zip(qps, xs))
    gaps = [abs(q.objective(x) - q.obj_ours) / (1.0 + abs(q.obj_ours)) for q, x in zip(qps, xs)]
    worse = max(
        (q.objective(x) - q.obj_ours) / (1.0 + abs(q.obj_ours)) for q, x in zip(qps, xs)
    )
    return dx, max(gaps), worse


def record(args):
    cmd = ["cargo", "run", "--release", "-q", "-p", "host-sim", "--", "qp-corpus",
           "--out", args.corpus, "--time", "--time-reps", str(args.ours_reps)]
    cmd += args.scenario.split()
    print("$ " + " ".join(cmd), flush=True)
    subprocess.run(cmd, check=True, cwd=os.path.join(os.path.dirname(__file__), ".."))


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--corpus", default="out/qp", help="corpus directory (qp_*.json)")
    ap.add_argument("--record", action="store_true",
                    help="first run `host-sim qp-corpus --out CORPUS --time` (cargo)")
    ap.add_argument("--reps", type=int, default=5, help="repetitions per QP of each peer")
    ap.add_argument("--proxsuite-reps", type=int, default=1,
                    help="repetitions per QP for proxsuite (ms per solve)")
    ap.add_argument("--ours-reps", type=int, default=21, help="--time-reps with --record")
    ap.add_argument("--scenario", default="",
                    help="extra qp-corpus options with --record, e.g. "
                         "'--track paper --obstacles paper --steps 1000'")
    ap.add_argument("--skip", default="", help="comma list of peers to skip: daqp,proxsuite")
    args = ap.parse_args()
    if args.reps < 1:
        sys.exit("--reps must be at least 1")
    if args.record:
        record(args)
    files = sorted(glob.glob(os.path.join(args.corpus, "qp_*.json")))
    if not files:
        sys.exit(f"no qp_*.json in {args.corpus}: run with --record, or "
                 "`cargo run --release -p host-sim -- qp-corpus --out DIR --time`")
    qps = []
    for p in files:
        with open(p) as fh:
            qps.append(Qp(json.load(fh)))
    if any(q.cold_us is None or q.warm_us is None for q in qps):
        sys.exit(f"{args.corpus} has no solve_us_cold/solve_us_warm: write it with "
                 "`host-sim qp-corpus --time` (or pass --record)")
    skip = set(filter(None, args.skip.split(",")))
    print(f"{len(qps)} QPs from {args.corpus}: {qps[0].n} inputs, "
          f"{min(q.m for q in qps)}-{max(q.m for q in qps)} rows "
          f"({min(q.standard()[0].shape[0] for q in qps)}-"
          f"{max(q.standard()[0].shape[0] for q in qps)} variables with explicit slacks)")
    print(f"machine: {platform.processor() or platform.machine()}, {os.cpu_count()} cores, "
          f"python {platform.python_version()}")

    ours_cold = [q.cold_us for q in qps]
    ours_warm = [q.warm_us for q in qps]
    rows = [("ours f64", "cold", ours_cold, None, [0.0, 0.0, 0.0], ""),
            ("ours f64", "warm", ours_warm, None, [0.0, 0.0, 0.0],
             f"iterations median {int(np.median([q.iters_ours for q in qps]))}")]

    if "daqp" not in skip:
        import daqp  # noqa: F401
        for form in ("native", "slack"):
            r = run_daqp(qps, form, args.reps)
            acc = accuracy(qps, r["x"])
            bad = sum(1 for fl in r["flag"] if fl not in (1, 2))
            name = f"DAQP {form}"
            for mode in ("cold", "warm"):
                note = (f"solve only p50 {percentile(r[mode + '_solve'], 0.5):.1f} "
                        f"p99 {percentile(r[mode + '_solve'], 0.99):.1f}; iterations median "
                        f"{int(np.median(r['it_' + mode]))}")
                if bad:
                    note += f"; {bad} exit flags not 1/2"
                rows.append((name, mode, r[mode], r[mode + "_solve"], acc, note))
    if "proxsuite" not in skip:
        r = run_proxsuite(qps, max(args.proxsuite_reps, 1))
        acc = accuracy(qps, r["x"])
        note = f"iterations median {int(np.median(r['it_cold']))}; setup + solve"
        rows.append(("proxsuite dense", "cold", r["cold"], None, acc, note))

    print()
    print("| solver | start | p50 µs | p99 µs | p50 / ours | p99 / ours | max |Δx| "
          "| max obj. gap | notes |")
    print("|---|---|---|---|---|---|---|---|---|")
    ours = {"cold": ours_cold, "warm": ours_warm}
    for name, mode, ts, _solve, acc, note in rows:
        p50, p99 = percentile(ts, 0.5), percentile(ts, 0.99)
        o50, o99 = percentile(ours[mode], 0.5), percentile(ours[mode], 0.99)
        print(f"| {name} | {mode} | {p50:.1f} | {p99:.1f} | {p50 / o50:.2f} | {p99 / o99:.2f} "
              f"| {acc[0]:.1e} | {acc[1]:.1e} | {note} |")
    print()
    print(f"obj. gap = |J − J_ours| / (1 + |J_ours|) on the native objective; tolerance "
          f"{OBJ_TOL:g}. A ratio > 1 means the peer is slower than ours.")
    failed = [(name, mode) for name, mode, _t, _s, acc, _n in rows if acc[1] > OBJ_TOL]
    if failed:
        print(f"ACCURACY: {failed} differ from ours by more than {OBJ_TOL:g}")
        return 1
    return 0


if __name__ == "__main__":
    sys.exit(main())
