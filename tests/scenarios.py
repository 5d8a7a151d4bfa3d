"""Shared test scenarios (imported by several test modules): a random linear-Gaussian problem
for the closed-form oracles, and a simulated drive whose GNSS jumps for good."""

from __future__ import annotations

from dataclasses import replace

import numpy as np


def linear_problem(seed=1, n=4, m=2, steps=8):
    """``(Phi, Q, H, R, x0, P0, zs)``: a near-constant-velocity chain of ``n`` states, ``m``
    random measurements, ``steps`` measurement vectors (random, not drawn from the model)."""
    rng = np.random.default_rng(seed)
    dt = 0.5
    Phi = np.eye(n) + np.diag(np.full(n - 1, dt), 1)
    A = rng.normal(size=(n, n))
    Q = 0.01 * A @ A.T + 1e-3 * np.eye(n)
    H = rng.normal(size=(m, n))
    R = np.diag(rng.uniform(0.5, 2.0, m))
    x0 = rng.normal(size=n)
    B = rng.normal(size=(n, n))
    P0 = B @ B.T + np.eye(n)
    zs = [rng.normal(size=m) * 3 for _ in range(steps)]
    return Phi, Q, H, R, x0, P0, zs


def gnss_jump_recording(jump_east_m=20.0, at_s=150.0, duration_s=240.0, seed=8):
    """A simulated drive (still 30 s) whose GNSS jumps ``jump_east_m`` east for good at
    ``at_s``: the gate rejects the fixes for ``reanchor_after_s``, then one is forced."""
    from navpp.simulate import SimulationSpec, simulate

    rec = simulate(SimulationSpec(duration_s=duration_s, still_s=30.0, seed=seed)).recording()
    g = rec.gnss
    lon = np.array(g.lon_deg, dtype=float)
    step = g.t >= at_s
    lon[step] += np.degrees(jump_east_m / (6.39e6 * np.cos(np.radians(g.lat_deg[step]))))
    return replace(rec, gnss=replace(g, lon_deg=lon))


def load_benchmark(name: str):
    """The module ``benchmarks/<name>.py`` (benchmarks are scripts, not a package), so a test
    can run the very code whose figures the README quotes."""
    import importlib.util
    from pathlib import Path

    path = Path(__file__).resolve().parents[1] / "benchmarks" / f"{name}.py"
    spec = importlib.util.spec_from_file_location(name, path)
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


def spline_samples(rng, n, kind, gaps, shift=False):
    """``(t, y)``: ``n`` stamps (s) and values for the spline tests.  ``kind`` 2: an even 8 ms grid
    far from 0 (1.7e9 s); else stamps 8-9 ms apart, with ``kind`` 1 ``gaps`` gaps of 0.1 to 100 s,
    moved by 100 s times a normal draw when ``shift``.  The values: a random walk over six decades."""
    if kind == 2:
        t = np.arange(1.7e9 + rng.random(), 1.7e9 + 1.0 + n * 0.008, 0.008)[:n]
    else:
        dt = 0.008 + 0.001 * rng.random(n)
        if kind == 1:
            dt[rng.integers(0, n, gaps)] += 10.0 ** rng.uniform(-1, 2, gaps)
        t = np.cumsum(dt)
        if shift:
            t = t + 100.0 * rng.normal()
    y = np.cumsum(rng.standard_normal(n)) * 10.0 ** rng.uniform(-3, 3)
    return t, y
