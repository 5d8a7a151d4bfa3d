"""Spreads of the Monte Carlo figures (navpp/papers/montecarlo.py) and the INS benchmark's
filter specs (benchmarks/bench_filters.py)."""

from __future__ import annotations

import importlib.util
from pathlib import Path

import numpy as np
import pytest

from navpp.papers.montecarlo import Stats, paired_rmse_difference, rmse, rmse_interval, spread_note


def _stats(err, runs):
    R, N, _ = err.shape
    return Stats(err, np.zeros((R, N)), np.zeros(R), {}, 0, [], runs=np.asarray(runs))


def test_interval_and_paired_difference_against_closed_forms():
    rng = np.random.default_rng(3)
    e = rng.normal(size=(40, 25, 2))
    a = _stats(e, range(40))
    b = _stats(1.1 * e, range(40))                       # every run's error 10 % larger
    value, sd, half = rmse_interval(a.err, (0, 1))
    assert value == rmse(a.err, (0, 1))
    per_run = np.sqrt(np.mean(np.sum(e ** 2, axis=-1), axis=-1))
    assert sd == pytest.approx(np.std(per_run, ddof=1), rel=1e-12)
    assert 0.0 < half < 3 * sd / np.sqrt(40)             # the mean's interval, not a run's spread
    diff, dhalf, n = paired_rmse_difference(b, a, (0, 1))
    # pooled RMSE scales exactly: the difference is 0.1 RMSE and every resample gives 0.1 of its own
    assert diff == pytest.approx(0.1 * value, rel=1e-12) and n == 40
    assert dhalf == pytest.approx(0.1 * half, rel=0.05)
    same, zero, _ = paired_rmse_difference(a, a, (0, 1))
    assert same == 0.0 and zero == 0.0


def test_paired_difference_uses_only_the_runs_both_completed():
    rng = np.random.default_rng(4)
    e = rng.normal(size=(10, 5, 1))
    a = _stats(e, range(10))
    b = _stats(e[[0, 2, 4]] * 2.0, [0, 2, 4])            # b diverged on the other runs
    diff, _, n = paired_rmse_difference(b, a, (0,))
    assert n == 3
    assert diff == pytest.approx(rmse(e[[0, 2, 4]], (0,)), rel=1e-12)   # 2x - 1x over those runs
    note = spread_note({"a": a, "b": b}, (0,), "position", "a")
    assert "b " in note and "vs a" in note and note.count("vs a") == 1


def test_bench_filters_splits_specs_outside_brackets():
    path = Path(__file__).resolve().parents[1] / "benchmarks" / "bench_filters.py"
    spec = importlib.util.spec_from_file_location("bench_filters", path)
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    assert mod.split_specs("ekf, aukf[max_fading=2; fade=observed],rwckf[candidates=1]") == [
        "ekf", "aukf[max_fading=2; fade=observed]", "rwckf[candidates=1]"]
    assert mod.paired({0: 1.0, 1: 2.0, 2: 4.0}, {0: 0.5, 2: 1.0}).tolist() == [0.5, 3.0]
