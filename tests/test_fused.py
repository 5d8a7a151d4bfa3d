"""The loop's compiled path (navpp.engine.fused) against the generic loop (the oracle): the same
run with the path on and off gives the same result bit for bit, on drives that exercise what the
kernel runs (fixes, coasting stops, a noise profile, stops with ZUPT and ZARU alone) and what it
leaves to the generic loop (a car's NHC with its standstill aids, GNSS velocity, a long IMU gap,
rejected and forced fixes, vetoed still runs), and filters other than the plain EKF never take it."""

from __future__ import annotations

import dataclasses
from dataclasses import replace

import numpy as np
import pytest
from scenarios import gnss_jump_recording

from navpp import aiding, api, engine
from navpp.config import config_from_dict
from navpp.engine import fused
from navpp.filters.ekf import EKF
from navpp.simulate import SimulationSpec, simulate


def _same(a: object, b: object, where: str = "result") -> None:
    """``a`` and ``b`` equal bit for bit (arrays by their bytes, NaN included), walking
    dataclasses, dicts and sequences; run times are left out."""
    if isinstance(a, np.ndarray):
        assert isinstance(b, np.ndarray) and a.shape == b.shape and a.dtype == b.dtype, where
        assert np.ascontiguousarray(a).tobytes() == np.ascontiguousarray(b).tobytes(), where
    elif dataclasses.is_dataclass(a) and not isinstance(a, type):
        for f in dataclasses.fields(a):
            if f.name not in ("runtime_s", "compile_s"):
                _same(getattr(a, f.name), getattr(b, f.name), f"{where}.{f.name}")
    elif isinstance(a, dict):
        assert isinstance(b, dict) and a.keys() == b.keys(), where
        for key in a:
            _same(a[key], b[key], f"{where}[{key!r}]")
    elif isinstance(a, (list, tuple)):
        assert isinstance(b, (list, tuple)) and len(a) == len(b), where
        for i, (p, q) in enumerate(zip(a, b)):
            _same(p, q, f"{where}[{i}]")
    elif isinstance(a, float):
        assert a == b or (a != a and b != b), where
    else:
        assert a == b, where


def _both(rec, cfg, monkeypatch: pytest.MonkeyPatch, name: str = "ekf", smooth: bool = False,
          still: list | None = None, rejected: list | None = None):
    """The run with the compiled path and without; the number of epochs the kernel ran (and in
    ``still``, ``rejected``, when given, the number of still epochs and of rejected fixes among
    them)."""
    ran = [0]
    kernel = fused.ekf_epochs

    def counted(*args):
        out = kernel(*args)
        ran[0] += out[0] - args[8]
        if still is not None:
            still.append(int(args[45][args[8]:out[0]].sum()))      # ep_cons
        if rejected is not None:
            fixes = args[4][args[8]:out[0]]                          # ep_fix
            rejected.append(int((~args[20][fixes[fixes >= 0]]).sum()))     # accepted_out
        return out

    monkeypatch.setattr(fused, "ekf_epochs", counted)
    on = engine.run(rec, cfg, api.make_filter(name, cfg), smooth=smooth)
    monkeypatch.setattr(fused, "ENABLED", False)
    off = engine.run(rec, cfg, api.make_filter(name, cfg), smooth=smooth)
    return on, off, ran[0]


def _with_imu_gap(rec, t0: float, t1: float):
    """``rec`` without its IMU samples in ``(t0, t1)`` s (a long gap the INS bridges)."""
    imu = rec.imu
    keep = (imu.t <= t0) | (imu.t >= t1)
    sliced = {f.name: getattr(imu, f.name)[keep] for f in dataclasses.fields(imu)
              if isinstance(getattr(imu, f.name), np.ndarray) and getattr(imu, f.name).shape[:1] == imu.t.shape}
    return replace(rec, imu=replace(imu, **sliced))


@pytest.mark.parametrize("smooth", [False, True])
def test_consumer_car_drive_is_bit_identical(monkeypatch: pytest.MonkeyPatch, smooth: bool) -> None:
    """Vibration (a noise profile), stale samples, a 15 s GNSS gap (coasting stops), a lever arm,
    a standstill (ZUPT and ZARU epochs, generic) and a long IMU gap (generic): the same bits,
    forward and smoothed (the kernel's states replayed into the smoother's store), with short
    stretches (each kernel call's buffers fresh)."""
    rec = simulate(SimulationSpec(duration_s=150.0, realism="consumer-car", lever_arm_m=(0.4, -0.2, 1.1),
                                  seed=3)).recording()
    rec = _with_imu_gap(rec, 100.0, 100.6)
    cfg = config_from_dict({"imu": {"preset": "consumer"}, "gnss": {"lever_arm_m": [0.4, -0.2, 1.1]}}, "test")
    monkeypatch.setattr(fused, "STRETCH", 50)
    monkeypatch.setattr(fused, "STORE_STRETCH", 7)
    on, off, ran = _both(rec, cfg, monkeypatch, smooth=smooth)
    assert ran > 200 and (on.smoothed is not None) == smooth
    _same(on, off)


@pytest.mark.parametrize("smooth", [False, True])
def test_standstill_epochs_are_bit_identical(monkeypatch: pytest.MonkeyPatch, smooth: bool) -> None:
    """Stops with ZUPT and ZARU alone (the default vehicle, no GNSS velocity): the kernel runs the
    still epochs too, with and without a fix, forward and smoothed, in short stretches."""
    rec = simulate(SimulationSpec(duration_s=300.0, still_s=20.0, seed=7)).recording()
    cfg = config_from_dict({"imu": {"preset": "automotive"}}, "test")
    monkeypatch.setattr(fused, "STRETCH", 50)
    monkeypatch.setattr(fused, "STORE_STRETCH", 7)
    still: list[int] = []
    on, off, ran = _both(rec, cfg, monkeypatch, smooth=smooth, still=still)
    counts = on.updates
    assert ran > 1000 and sum(still) > 100 and counts["zupt"]["applied"] > 100 and counts["zaru"]["applied"] > 100
    _same(on, off)


def test_vetoed_still_runs_are_bit_identical(monkeypatch: pytest.MonkeyPatch) -> None:
    """ZUPT's consistency check with a limit so low that it vetoes still runs: the kernel leaves the
    vetoing epoch to the generic loop and takes up the still run's state after it."""
    rec = simulate(SimulationSpec(duration_s=300.0, still_s=20.0, seed=7)).recording()
    cfg = config_from_dict({"imu": {"preset": "automotive"}}, "test")
    monkeypatch.setattr(aiding, "ZUPT_Z", 0.3)
    still: list[int] = []
    on, off, _ = _both(rec, cfg, monkeypatch, still=still)
    assert on.calibration["standstill_ended_early_s"] and sum(still) > 0
    _same(on, off)


@pytest.mark.parametrize("smooth", [False, True])
def test_rejected_and_forced_fixes_are_bit_identical(monkeypatch: pytest.MonkeyPatch, smooth: bool) -> None:
    """A GNSS jump: fixes rejected for 10 s (the kernel records them), then one forced through
    the gate (a generic epoch between kernel stretches), forward and smoothed."""
    cfg = config_from_dict({"imu": {"preset": "automotive"}}, "test")
    rejected: list[int] = []
    on, off, ran = _both(gnss_jump_recording(duration_s=200.0), cfg, monkeypatch, smooth=smooth,
                         rejected=rejected)
    diag = on.diagnostics
    assert ran > 200 and np.any(diag.forced) and not np.all(diag.accepted)
    assert sum(rejected) == int((~diag.accepted).sum()) > 10
    _same(on, off)


def test_gnss_velocity_epochs_stay_generic(monkeypatch: pytest.MonkeyPatch) -> None:
    """Fixes with a GNSS velocity are the generic loop's: the kernel runs none of them."""
    rec = simulate(SimulationSpec(duration_s=90.0, still_s=20.0, gnss_velocity=True, seed=5)).recording()
    cfg = config_from_dict({"imu": {"preset": "automotive"}}, "test")
    on, off, ran = _both(rec, cfg, monkeypatch)
    assert ran == 0
    _same(on, off)


@pytest.mark.parametrize("name", ["aekf", "ckf"])
def test_other_filters_take_the_generic_loop(name: str, monkeypatch: pytest.MonkeyPatch) -> None:
    """Only the plain EKF runs the compiled path; an EKF whose update was replaced does not."""
    cfg = config_from_dict({"imu": {"preset": "automotive"}}, "test")
    assert not fused.plain_ekf(api.make_filter(name, cfg))
    assert fused.plain_ekf(api.make_filter("ekf", cfg))
    monkeypatch.setattr(EKF, "update", lambda self, state, model, meas: None)
    assert not fused.plain_ekf(api.make_filter("ekf", cfg))


def test_interpreted_kernels_take_the_generic_loop(monkeypatch: pytest.MonkeyPatch) -> None:
    """With the kernels interpreted (``--jit off``) the fused kernel's loops would run as Python,
    no faster than the generic loop: the path is not taken, and the result is the same."""
    cfg = config_from_dict({"imu": {"preset": "automotive"}}, "test")
    rec = simulate(SimulationSpec(duration_s=60.0, seed=5)).recording()
    on, _, ran = _both(rec, cfg, monkeypatch)
    assert ran > 0
    monkeypatch.setattr(fused, "ENABLED", True)
    monkeypatch.setattr(fused, "interpreted", lambda: True)
    interp, _, ran_interp = _both(rec, cfg, monkeypatch)
    assert ran_interp == 0
    _same(on, interp)

