#!/usr/bin/env python3
"""`mmenn estimate` end to end against the same job in pandas + scipy, in one run.

Usage: python3 xtask/bench/estimate_vs_scipy.py MMENN_BINARY WORK_DIR [SAMPLES]

The record: `mmenn simulate --system msd_cubic` (mass-spring-damper with a cubic spring,
position measured, noise variance 0.09 given in the model file) at 100 Hz for
SAMPLES/100 s (default 200 000 samples). Both sides solve the same problem: the linear
MME problem of the model file with W fixed (the value mmenn's automatic search picks on
the same record, found by one untimed `mmenn estimate` first), the noise variance given,
one sub-step per sample:

    x_{k+1} = Phi x_k + Gamma_u u_k + Gamma_d d_k   (exact zero-order-hold discretisation)
    J = sum_k (y_k - C x_k)^2 / R + sum_k dt d_k' W d_k,  minimised over x_0 and every d_k.

mmenn (timed): `mmenn estimate --w W --substeps 1`: reads the CSV, runs its Riccati sweep,
writes estimate.csv, summary.json, report.md, report.html and its SVG figures.

pandas + scipy (timed, one thread for BLAS): pandas.read_csv; the optimality (KKT)
conditions of J as one banded linear system in (x_k, d_k, lambda_k) interleaved, solved by
scipy.linalg.solve_banded (LAPACK gbsv); x-hat and d-hat written with DataFrame.to_csv and
a JSON summary. It draws no figures (matplotlib is not required), so it does less work
than mmenn. If pandas is missing, numpy.loadtxt/savetxt stand in and the output says so.

Each side runs REPEATS times, alternating; the minimum wall time and the minimum CPU
time (user + system: of the child process for mmenn, of this process for the peer) are
reported. CPU time is the steadier number on a machine shared with other work. The two estimates are
compared (largest difference of x-hat relative to the range of x) to show it is the same
job.
"""

import json
import os
import resource
import subprocess
import sys
import time

for var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(var, "1")

import numpy as np  # noqa: E402
from scipy.linalg import expm, solve_banded  # noqa: E402

try:
    import pandas as pd  # noqa: E402
except ImportError:  # pragma: no cover - reported in the output
    pd = None

REPEATS = 5


def run(cmd):
    subprocess.run(cmd, check=True, stdout=subprocess.DEVNULL)


def read_model(path):
    """The few keys of the simulated model file this job needs (plain TOML subset)."""
    try:
        import tomllib
    except ImportError:  # Python < 3.11
        import tomli as tomllib
    with open(path, "rb") as f:
        return tomllib.load(f)


def discretise(a, b, e, dt):
    """Phi, Gamma_u, Gamma_d of the exact zero-order hold (one block exponential)."""
    n, m, q = a.shape[0], b.shape[1], e.shape[1]
    big = np.zeros((n + m + q, n + m + q))
    big[:n, :n] = a
    big[:n, n:n + m] = b
    big[:n, n + m:] = e
    ex = expm(big * dt)
    return ex[:n, :n], ex[:n, n:n + m], ex[:n, n + m:]


def peer(data_csv, model, w, out_dir):
    """The whole job in Python: read, solve, write. Returns x-hat (N x n)."""
    if pd is not None:
        df = pd.read_csv(data_csv)
        t = df["t"].to_numpy()
        u = df[model["inputs"]].to_numpy()
        y = df[model["measured"]].to_numpy()
    else:
        raw = np.loadtxt(data_csv, delimiter=",", skiprows=1)
        with open(data_csv) as f:
            header = f.readline().strip().split(",")
        t = raw[:, header.index("t")]
        u = raw[:, [header.index(c) for c in model["inputs"]]]
        y = raw[:, [header.index(c) for c in model["measured"]]]
    states = model["states"]
    a = np.array(model["A"], dtype=float)
    b = np.array(model["B"], dtype=float)
    n, m = a.shape[0], b.shape[1]
    meas = [states.index(s) for s in model["measured"]]
    corr = [states.index(s) for s in model["corrected"]]
    q = len(corr)
    c = np.zeros((len(meas), n))
    c[np.arange(len(meas)), meas] = 1.0
    e = np.zeros((n, q))
    e[corr, np.arange(q)] = 1.0
    r = np.array(model["noise_variance"], dtype=float)
    dt = t[1] - t[0]
    phi, gu, gd = discretise(a, b, e, dt)
    N = len(t)
    blk = 2 * n + q  # x_k, d_k, lambda_k
    size = (N - 1) * blk + n
    rows, cols, vals = [], [], []

    def put(r0, c0, mat, ks):
        """mat at block offsets r0 + k*blk, c0 + k*blk for every k in ks."""
        ii, jj = np.nonzero(mat)
        for i, j in zip(ii, jj):
            rows.append(r0 + i + ks * blk)
            cols.append(c0 + j + ks * blk)
            vals.append(np.full(len(ks), mat[i, j]))

    all_k = np.arange(N)
    inner = np.arange(N - 1)
    hxx = 2.0 * c.T @ np.diag(1.0 / r) @ c
    put(0, 0, hxx, all_k)                              # x_k: 2 C'R^-1 C
    put(n, n, 2.0 * dt * w * np.eye(q), inner)         # d_k: 2 h W
    put(0, n + q, phi.T, inner)                        # x_k row: Phi' lambda_k
    put(blk, n + q, -np.eye(n), inner)                 # x_{k+1} row: -lambda_k
    put(n, n + q, gd.T, inner)                         # d_k row: Gamma_d' lambda_k
    put(n + q, 0, phi, inner)                          # lambda_k row: Phi x_k
    put(n + q, n, gd, inner)                           # ... + Gamma_d d_k
    put(n + q, blk, -np.eye(n), inner)                 # ... - x_{k+1}
    rows = np.concatenate(rows)
    cols = np.concatenate(cols)
    vals = np.concatenate(vals)
    lower = int((rows - cols).max())
    upper = int((cols - rows).max())
    ab = np.zeros((lower + upper + 1, size))
    ab[upper + rows - cols, cols] = vals
    rhs = np.zeros(size)
    obs = 2.0 * (y / r) @ c                            # 2 C'R^-1 y_k, N x n
    idx = np.arange(N)[:, None] * blk + np.arange(n)[None, :]
    rhs[idx.ravel()] = obs.ravel()
    cu = u[:-1] @ gu.T                                 # Gamma_u u_k
    lidx = np.arange(N - 1)[:, None] * blk + n + q + np.arange(n)[None, :]
    rhs[lidx.ravel()] = -cu.ravel()
    z = solve_banded((lower, upper), ab, rhs, overwrite_ab=True, check_finite=False)
    x = z[idx]
    didx = np.arange(N - 1)[:, None] * blk + n + np.arange(q)[None, :]
    d = np.vstack([z[didx], np.full((1, q), np.nan)])
    resid = y - x @ c.T
    os.makedirs(out_dir, exist_ok=True)
    columns = {"t": t}
    columns.update({s: x[:, i] for i, s in enumerate(states)})
    columns.update({f"d_{s}": d[:, j] for j, s in enumerate(model["corrected"])})
    if pd is not None:
        pd.DataFrame(columns).to_csv(os.path.join(out_dir, "estimate.csv"), index=False)
    else:
        np.savetxt(os.path.join(out_dir, "estimate.csv"), np.column_stack(list(columns.values())),
                   delimiter=",", header=",".join(columns), comments="")
    summary = {
        "samples": N,
        "residual_variance": dict(zip(model["measured"], resid.var(axis=0).tolist())),
        "w": w,
    }
    with open(os.path.join(out_dir, "summary.json"), "w") as f:
        json.dump(summary, f, indent=2)
    return x


def main():
    if len(sys.argv) < 3:
        sys.exit(__doc__)
    mmenn, work = sys.argv[1], sys.argv[2]
    samples = int(sys.argv[3]) if len(sys.argv) > 3 else 200_000
    os.makedirs(work, exist_ok=True)
    rec = os.path.join(work, "record")
    run([mmenn, "--quiet", "--force", "simulate", "--system", "msd_cubic", "--seed", "1",
         "--duration", str((samples - 1) / 100.0), "--out", rec])
    data_csv, model_toml = os.path.join(rec, "data.csv"), os.path.join(rec, "model.toml")
    model = read_model(model_toml)
    # W as mmenn's automatic search picks it (untimed), then both sides use it.
    auto = os.path.join(work, "auto")
    run([mmenn, "--quiet", "--force", "estimate", "--data", data_csv, "--model", model_toml,
         "--substeps", "1", "--out", auto])
    with open(os.path.join(auto, "summary.json")) as f:
        w = float(next(iter(json.load(f)["w_by_correction"].values())))

    mm_out = os.path.join(work, "mmenn")
    py_out = os.path.join(work, "scipy")
    mm_times, mm_cpu, py_times, py_cpu = [], [], [], []

    def child_cpu():
        r = resource.getrusage(resource.RUSAGE_CHILDREN)
        return r.ru_utime + r.ru_stime

    for _ in range(REPEATS):
        c0, t0 = child_cpu(), time.perf_counter()
        run([mmenn, "--quiet", "--force", "estimate", "--data", data_csv, "--model",
             model_toml, "--w", repr(w), "--substeps", "1", "--out", mm_out])
        mm_times.append(time.perf_counter() - t0)
        mm_cpu.append(child_cpu() - c0)
        c0, t0 = time.process_time(), time.perf_counter()
        x_py = peer(data_csv, model, w, py_out)
        py_times.append(time.perf_counter() - t0)
        py_cpu.append(time.process_time() - c0)

    est = np.genfromtxt(os.path.join(mm_out, "estimate.csv"), delimiter=",", names=True)
    x_mm = np.column_stack([est[s] for s in model["states"]])
    span = x_mm.max(axis=0) - x_mm.min(axis=0)
    rel = float((np.abs(x_mm - x_py).max(axis=0) / span).max())
    figures = sorted(f for f in os.listdir(mm_out) if f.endswith(".svg"))
    fig_bytes = sum(os.path.getsize(os.path.join(mm_out, f)) for f in figures)
    out_bytes = sum(os.path.getsize(os.path.join(mm_out, f)) for f in os.listdir(mm_out))
    with open(os.path.join(mm_out, "summary.json")) as f:
        phases = json.load(f).get("phase_seconds", {})
    print(f"record: {len(x_mm)} samples, W = {w:.6g}, one sub-step per sample")
    print(f"mmenn estimate (CSV in; CSV, summary, report.md/html, {len(figures)} SVG figures "
          f"= {fig_bytes / 1e6:.2f} MB of {out_bytes / 1e6:.2f} MB out): "
          f"wall {min(mm_times):.3f} s (runs: {', '.join(f'{s:.3f}' for s in mm_times)}), "
          f"CPU {min(mm_cpu):.3f} s; "
          f"phases of the last run (its summary.json): "
          + ", ".join(f"{k} {v:.3f} s" for k, v in sorted(phases.items())))
    reader = f"pandas {pd.__version__}" if pd is not None else "numpy (pandas missing)"
    import scipy
    print(f"{reader} + scipy {scipy.__version__} solve_banded (CSV in; CSV and summary out, no "
          f"figures): wall {min(py_times):.3f} s (runs: "
          f"{', '.join(f'{s:.3f}' for s in py_times)}), CPU {min(py_cpu):.3f} s")
    print(f"ratio peer / mmenn: wall {min(py_times) / min(mm_times):.1f}x, "
          f"CPU {min(py_cpu) / min(mm_cpu):.1f}x")
    print(f"largest |x-hat difference| / range of the state: {rel:.2e}")


if __name__ == "__main__":
    main()
