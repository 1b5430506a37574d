"""EMPS: can the test record's pulses_N column be the force on the load?

Simulates the calibrated grey box of the reproduced EMPS table (coefficients from
docs/results/tables/real_emps.md: v' = a·u − b·v − c·tanh(v/3e-4) + off, y' = v, mass
M = gτ/a with gτ = 35.15 N/V) on the official test record with scipy's LSODA, once
without the pulses and once with ±pulses_N/M added to the acceleration, from the measured
start (y[0], a 5-sample difference for v). Prints the RMSE after the 20-sample window.
Measured on 2026-11-26 (2-core VM): 6.46 mm without, 148 mm with +, 131 mm with −.

    python3 xtask/bench/emps_pulses.py [path/to/emps/validation.csv]
"""
import sys

import numpy as np
from scipy.integrate import solve_ivp

path = sys.argv[1] if len(sys.argv) > 1 else "../shared/data/emps/validation.csv"
d = np.genfromtxt(path, delimiter=",", names=True)
t, u, y, p = d["t"], d["u"], d["y"], d["pulses_N"]
a, b, c, off = 0.388479, 2.12438, 0.241725, 0.037331
mass = 35.15 / a
dt = t[1] - t[0]


def run(sign, x0):
    xs = [np.array(x0)]
    x = np.array(x0)
    for k in range(len(t) - 1):
        def f(_s, x, k=k):
            acc = a * u[k] - b * x[1] - c * np.tanh(x[1] / 3e-4) + off + sign * p[k] / mass
            return [x[1], acc]

        x = solve_ivp(f, (0, dt), x, method="LSODA", rtol=1e-8, atol=1e-10).y[:, -1]
        xs.append(x)
    return np.array(xs)


x0 = [y[0], (y[5] - y[0]) / (5 * dt)]
for sign in (0, 1, -1):
    e = (run(sign, x0)[20:, 0] - y[20:]) * 1000
    print(f"pulse sign {sign:+d}: test RMSE {np.sqrt(np.mean(e**2)):.2f} mm")
