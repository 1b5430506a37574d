#!/usr/bin/env python3
"""MINPACK's Levenberg-Marquardt (scipy.optimize.least_squares(method='lm')) on the same
network, data and initial weights as `cargo run --release -p nn --example lm_vs_scipy`,
and the time each optimiser needs to reach the same training MSE.

Usage: python3 crates/nn/benches/scipy_lm.py OUT_DIR [--reuse-scipy]
(OUT_DIR written by the example). scipy's evaluation logs are saved in OUT_DIR/scipy.json,
keyed by N, H and the initial-weight seed; with --reuse-scipy they are read from there
instead of rerunning scipy (for iterating on the Rust side; the initial weights must match,
which is checked). With several seeds per (N, H) the script also prints, per cell, the
median over seeds of the end-to-end ratio, and how many cells reach 5x.

The network is nn's 3-H-1 tanh MLP acting on the scaled data written by the example, with
nn's flat weight layout: per hidden unit [w1 w2 w3 b], then [v1 .. vH c]. Residuals are
rho*(t_scaled - y_scaled), i.e. errors in the target's original units, as nn's
ErrorSpace::Original. The Jacobian is analytic (MINPACK lmder).

The Rust side records two clocks: process CPU time (all threads) and wall-clock time; with
one thread (the example's default) they agree on an idle machine. The table reports both
ratios against scipy's CPU time (scipy and its BLAS run on one thread).

Protocol, per case: both optimisers run from the same weights within their budgets
(Rust: the example's epoch budget; scipy: max_nfev = 2 x that budget, tolerances 1e-15),
recording the training MSE and the elapsed time at every point they evaluate (Rust: after
every epoch; scipy: every residual evaluation). The common target is 1 % above the larger
of the two best MSEs (so both reach it), and each optimiser's time is the first elapsed
time at which its MSE is at or below the target. Times are CPU time on both sides
(time.thread_time here, CLOCK_PROCESS_CPUTIME_ID in the example), so other processes on a
shared machine do not inflate them much. Also reported: the cost of one iteration
(Rust: time per epoch; scipy: time per Jacobian evaluation), which does not depend on the
paths the two take. scipy's times are the minimum over REPEATS runs,
like the example's. BLAS threads are pinned to 1 (MINPACK and nn's LM are single-threaded).
"""

import json
import os
import sys
import time

for var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(var, "1")

import numpy as np  # noqa: E402
from scipy.optimize import least_squares  # noqa: E402

REPEATS = 3
# The common target is this factor above the worse of the two best MSEs, so that a slow
# final creep towards an optimiser's own minimum does not dominate its time.
TARGET_SLACK = 1.01


def unpack(w, h):
    """Hidden weights W (h x 3), biases b (h), output weights v (h), output bias c."""
    hid = w[: 4 * h].reshape(h, 4)
    out = w[4 * h:]
    return hid[:, :3], hid[:, 3], out[:h], out[h]


class Problem:
    def __init__(self, s, t, rho, h):
        self.s, self.t, self.rho, self.h = s, t, rho, h
        self.log = []  # (elapsed, mse, jacobians so far) at every residual evaluation
        self.start = 0.0
        self.njev = 0

    def residual(self, w):
        wh, b, v, c = unpack(w, self.h)
        a = np.tanh(self.s @ wh.T + b)
        r = self.rho * (self.t - (a @ v + c))
        self.log.append((time.thread_time() - self.start, float(r @ r) / r.size, self.njev))
        return r

    def jacobian(self, w):
        self.njev += 1
        wh, b, v, c = unpack(w, self.h)
        a = np.tanh(self.s @ wh.T + b)
        n = self.s.shape[0]
        jac = np.empty((n, 5 * self.h + 1))
        g = (1.0 - a * a) * v  # d y / d (hidden pre-activation), n x h
        hid = jac[:, : 4 * self.h].reshape(n, self.h, 4)
        hid[:, :, :3] = g[:, :, None] * self.s[:, None, :]
        hid[:, :, 3] = g
        jac[:, 4 * self.h: 5 * self.h] = a
        jac[:, 5 * self.h] = 1.0
        return -self.rho * jac


def run_scipy(s, t, rho, h, w0, max_nfev):
    p = Problem(s, t, rho, h)
    p.start = time.thread_time()
    least_squares(p.residual, np.array(w0), jac=p.jacobian, method="lm",
                  ftol=1e-15, xtol=1e-15, gtol=1e-15, max_nfev=max_nfev)
    return p.log, p.njev


def first_index(mses, target):
    for i, m in enumerate(mses):
        if m <= target:
            return i
    return None


def first_time(times, mses, target):
    i = first_index(mses, target)
    return float("nan") if i is None else times[i]


def main():
    out = sys.argv[1]
    reuse = "--reuse-scipy" in sys.argv[2:]
    rust = json.load(open(os.path.join(out, "rust.json")))
    cache_path = os.path.join(out, "scipy.json")
    cache = {}
    if reuse and os.path.exists(cache_path):
        cache = json.load(open(cache_path))
    budget = 2 * rust["max_epochs"]
    data = {}
    rows = []
    for case in rust["cases"]:
        n, h = case["n"], case["h"]
        if n not in data:
            d = np.loadtxt(os.path.join(out, f"data_N{n}.csv"), delimiter=",", skiprows=1)
            data[n] = (np.ascontiguousarray(d[:, :3]), np.ascontiguousarray(d[:, 3]))
        s, t = data[n]
        seed = case.get("seed", 11)
        key = f"{n}/{h}/{seed}"
        if key in cache and cache[key]["w0"] == case["w0"]:
            sp_mse, sp_time, sp_jev, njev = (cache[key][k] for k in ("mse", "time", "jev", "njev"))
        else:
            runs = [run_scipy(s, t, case["rho"], h, case["w0"], budget)
                    for _ in range(REPEATS)]
            logs = [log for log, _ in runs]
            njev = runs[0][1]
            # Same evaluation sequence every run (deterministic); elapsed = best over runs.
            sp_mse = [m for _, m, _ in logs[0]]
            sp_jev = [j for _, _, j in logs[0]]
            sp_time = [min(log[i][0] for log in logs) for i in range(len(logs[0]))]
            cache[key] = {"w0": case["w0"], "mse": sp_mse, "time": sp_time, "jev": sp_jev,
                          "njev": njev}
        r_mse, r_time = case["rust_mse"], case["rust_time"]
        r_wall = case.get("rust_wall", r_time)
        # MSE at w0 must agree: same network, data and weights.
        assert abs(sp_mse[0] - r_mse[0]) <= 1e-9 * r_mse[0], (sp_mse[0], r_mse[0])
        target = TARGET_SLACK * max(min(sp_mse), min(r_mse))
        tr, ts = first_time(r_time, r_mse, target), first_time(sp_time, sp_mse, target)
        tw = first_time(r_wall, r_mse, target)
        ir_hit, is_hit = first_index(r_mse, target), first_index(sp_mse, target)
        sp_iters = None if is_hit is None else sp_jev[is_hit]
        it_r = 1e3 * r_time[-1] / (len(r_time) - 1)
        it_s = 1e3 * sp_time[-1] / max(njev, 1)
        rows.append((n, h, seed, tr, tw, ts, min(r_mse), min(sp_mse), target, ir_hit,
                     sp_iters, it_r, it_s))
        print(f"N {n:>5} H {h:>2} seed {seed}: rust {tr:.4f} s CPU, {tw:.4f} s wall, "
              f"scipy {ts:.4f} s, ratio {ts / tr:.1f}, MSE rust {min(r_mse):.3e} "
              f"scipy {min(sp_mse):.3e} target {target:.3e}, per iteration {it_r:.2f} / {it_s:.2f} ms; to target: "
              f"rust {ir_hit} epochs, scipy {sp_iters} Jacobians ({is_hit} residuals)",
              file=sys.stderr)
    json.dump(cache, open(cache_path, "w"))
    threads = rust.get("threads", 1)
    damping = rust.get("damping", "Trainlm")
    acceleration = rust.get("acceleration", "None")
    print(f"Rust: {damping} damping, {acceleration} acceleration, {threads} thread(s); Rust time columns are process CPU "
          "time (all threads) and wall-clock time; scipy's is its thread's CPU time.")
    print()
    print("| N | H | seed | Rust CPU to target (s) | Rust wall to target (s) "
          "| scipy to target (s) | scipy / Rust CPU | scipy / Rust wall | best MSE Rust "
          "| best MSE scipy | target MSE | Rust epochs to target | scipy Jacobians to target "
          "| Rust CPU ms/epoch | scipy ms/iteration | per-iteration ratio |")
    print("|" + "---:|" * 16)
    for n, h, seed, tr, tw, ts, mr, ms, tg, er, es, ir, isp in rows:
        print(f"| {n} | {h} | {seed} | {tr:.4f} | {tw:.4f} | {ts:.4f} | {ts / tr:.1f} "
              f"| {ts / tw:.1f} | {mr:.3e} | {ms:.3e} | {tg:.3e} | {er} | {es} | {ir:.2f} "
              f"| {isp:.2f} | {isp / ir:.1f} |")

    summary(rows)


def summary(rows):
    """Per (N, H): the median over seeds of scipy / Rust (CPU), and the count of cells
    whose median reaches 5x."""
    cells = {}
    for n, h, seed, tr, _tw, ts, mr, ms, *_ in rows:
        cells.setdefault((n, h), []).append((ts / tr, mr, ms, seed))
    print()
    print("| N | H | scipy / Rust per seed | median | best MSE Rust per seed "
          "| best MSE scipy per seed |")
    print("|---:|---:|---|---:|---|---|")
    medians = []
    for (n, h), v in cells.items():
        ratios = [r for r, *_ in v]
        med = float(np.median(ratios))
        medians.append(med)
        print(f"| {n} | {h} | {' / '.join(f'{r:.1f}' for r in ratios)} | {med:.1f} "
              f"| {' / '.join(f'{m:.2e}' for _, m, _, _ in v)} "
              f"| {' / '.join(f'{m:.2e}' for _, _, m, _ in v)} |")
    print()
    print(f"cells: {len(medians)}; median ratio >= 5 in {sum(m >= 5 for m in medians)}; "
          f"median of medians {float(np.median(medians)):.1f}; "
          f"range {min(medians):.1f}-{max(medians):.1f}")


if __name__ == "__main__":
    main()
