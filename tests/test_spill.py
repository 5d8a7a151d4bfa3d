"""Issue 21 point 1: the IMU-rate output beyond ``[output] memory`` on an unlinked temporary
file whose pages each pass releases behind itself (:mod:`navpp.spill`): the same bits as in
memory, the pages out of the process, and the file gone afterwards, after an error too."""

from __future__ import annotations

import gc
import tempfile
from dataclasses import fields, replace
from pathlib import Path

import numpy as np
import pytest

from navpp import api, spill
from navpp.engine import output
from navpp.engine.recorder import OUTPUT_ROW_BYTES, new_path
from navpp.recording import Solution

DRIVE = Path(__file__).resolve().parents[1] / "sample_data" / "drive"


@pytest.fixture
def spill_dir(tmp_path, monkeypatch):
    """The spill files' directory (``$TMPDIR``) for the test, and small windows (several per array)."""
    monkeypatch.setattr(tempfile, "tempdir", str(tmp_path))
    monkeypatch.setattr(spill, "WINDOW_ROWS", 1000)
    monkeypatch.setattr(spill, "RELEASE_BYTES", 80_000)
    return tmp_path


def _mapped(directory: Path) -> list[str]:
    """This process's mappings of files in ``directory`` (unlinked ones included)."""
    with open("/proc/self/maps", encoding="ascii", errors="replace") as f:
        return [line for line in f if str(directory) in line]


def _rss_kb(a: np.ndarray) -> int:
    """Resident kB of the mapping ``a`` lives on (/proc/self/smaps)."""
    start = spill._mapping(a).address
    with open("/proc/self/smaps", encoding="ascii", errors="replace") as f:
        inside = False
        for line in f:
            if "-" in line.split(" ", 1)[0] and not line.startswith(("Rss", "Size")):
                lo = int(line.split("-", 1)[0], 16)
                inside = lo == start
            elif inside and line.startswith("Rss:"):
                return int(line.split()[1])
    raise AssertionError("mapping not found")


def test_spilled_rows_keep_their_values_after_release(spill_dir):
    a = spill.empty_rows(100_000, (10,), np.float64, spill=True)
    assert spill.spilled(a) and spill.spilled(a[5:, 7]) and not spill.spilled(np.empty(3))
    assert len(_mapped(spill_dir)) == 1 and not list(spill_dir.iterdir())    # unlinked at once
    values = np.arange(a.size, dtype=float).reshape(a.shape)
    a[:] = values
    assert _rss_kb(a) >= a.nbytes // 1024 - 4
    spill.release([a[:, 3]], 0, a.shape[0])                 # a column view releases its rows
    assert _rss_kb(a) <= 8
    assert np.array_equal(a, values)                         # read back from the file
    del a
    gc.collect()
    assert not _mapped(spill_dir)


def test_release_before_follows_a_writer_by_windows(spill_dir):
    a = spill.full_rows(50_000, (10,), np.nan, spill=True)
    assert _rss_kb(a) <= 8 and np.isnan(a).all()           # filled window by window
    spill.release([a], 0, a.shape[0])
    for i in range(a.shape[0]):
        a[i] = i
        spill.release_before(a, i)
    assert _rss_kb(a) <= spill.RELEASE_BYTES // 1024 + 8
    assert np.array_equal(a[:, 0], np.arange(a.shape[0], dtype=float))


def test_release_before_holds_bytes_not_rows(spill_dir, monkeypatch):
    """Per-fix records (M, 3, 3) written in order keep at most RELEASE_BYTES behind the writer,
    however many rows a window of a pass holds."""
    monkeypatch.setattr(spill, "WINDOW_ROWS", 1 << 16)      # 4.7 MB of these rows
    a = spill.full_rows(40_000, (3, 3), np.nan, spill=True)
    spill.release([a], 0, a.shape[0])
    for i in range(a.shape[0]):
        a[i] = i
        spill.release_before(a, i)
        if i % 4000 == 0:
            assert _rss_kb(a) <= spill.RELEASE_BYTES // 1024 + 8
    assert np.array_equal(a[:, 1, 2], np.arange(a.shape[0], dtype=float))


def test_new_path_spills_beyond_the_budget(spill_dir):
    assert not spill.spilled(new_path(1000))
    assert not spill.spilled(new_path(1000, 1000 * OUTPUT_ROW_BYTES))
    p = new_path(1000, 1000 * OUTPUT_ROW_BYTES - 1)
    assert spill.spilled(p) and p.shape == (1000, 10) and np.isnan(p).all()


def test_output_steps_give_the_same_bits_spilled(spill_dir):
    rng = np.random.default_rng(3)
    n = 5_500
    t = np.sort(rng.uniform(0, 100, n))
    q = rng.normal(size=(n, 4))
    q /= np.linalg.norm(q, axis=1, keepdims=True)
    rows = np.column_stack([q, rng.normal(0, 20, (n, 3)), np.radians(rng.uniform(-80, 80, n)),
                            np.radians(rng.uniform(-180, 180, n)), rng.normal(300, 50, n)])
    kept = new_path(n, 1)
    kept[:] = rows
    assert spill.spilled(kept)
    tg = np.sort(rng.uniform(0, 100, 40))
    var_prior, var_post = rng.uniform(1, 4, (40, 3)), rng.uniform(0.1, 1, (40, 3))
    std = output.interpolated_std_rows(t, -1.0, np.ones(3), tg, var_prior, var_post, like=kept)
    assert spill.spilled(std)
    assert np.array_equal(std, output.interpolated_std(t, -1.0, np.ones(3), tg, var_prior, var_post))
    gyro, bg = rng.normal(0, 0.1, (n, 3)), rng.normal(0, 1e-3, (40, 3))
    rate = output.body_rate(t, kept, gyro, tg, bg, np.zeros(3))
    assert spill.spilled(rate) and np.array_equal(rate, output.body_rate(t, rows, gyro, tg, bg, np.zeros(3)))
    a = output.solution_from_path(t, kept, std, 0)
    b = output.solution_from_path(t, rows.copy(), std, 0)
    assert np.array_equal(a.rph_deg, b.rph_deg, equal_nan=True) and np.array_equal(a.lat_deg, b.lat_deg)


def _arrays(sol: Solution) -> dict[str, np.ndarray]:
    return {f.name: np.array(getattr(sol, f.name)) for f in fields(sol)
            if isinstance(getattr(sol, f.name), np.ndarray)}


@pytest.mark.parametrize("smooth", [False, True])
def test_a_spilled_run_writes_the_same_bytes(spill_dir, tmp_path_factory, smooth, monkeypatch):
    from navpp.engine import recorder

    monkeypatch.setattr(recorder, "KNOT_CHUNK", 97)      # the spilled run's knots in many chunks
    cfg = api.resolve_config(DRIVE, None)
    outs = {}
    for budget in (1 << 30, 1):
        out = tmp_path_factory.mktemp(f"out{budget}")
        res = api.process(DRIVE, config=replace(cfg, output=replace(cfg.output, memory=budget)), out_dir=out,
                          write=True, smooth=smooth)
        assert spill.spilled(res.run.solution.lat_deg) == (budget == 1)
        outs[budget] = (out, _arrays(res.solution))
        del res
    gc.collect()
    assert not _mapped(spill_dir) and not list(spill_dir.iterdir())
    (d0, a0), (d1, a1) = outs[1 << 30], outs[1]
    assert a0.keys() == a1.keys() and all(np.array_equal(a0[k], a1[k], equal_nan=True) for k in a0)
    for f in ("trajectory.csv", "diagnostics.csv") + (("trajectory_forward.csv",) if smooth else ()):
        assert (d0 / f).read_bytes() == (d1 / f).read_bytes()


def test_the_spill_file_goes_on_an_interrupt(spill_dir):
    from navpp import engine

    cfg = api.resolve_config(DRIVE, None)
    cfg = replace(cfg, output=replace(cfg.output, memory=1))
    rec = api.read_log(DRIVE, cfg)
    assert len(_mapped(spill_dir)) == 3                     # the IMU's t, gyro and accel, spilled as read
    seen = []

    def interrupt(done: float) -> None:
        if done > 0.5:
            seen.append(len(_mapped(spill_dir)))
            raise KeyboardInterrupt

    with pytest.raises(KeyboardInterrupt):
        engine.run(rec, cfg, api.make_filter("ekf", cfg), progress=interrupt)
    del rec
    gc.collect()
    # the IMU's three, the path and the per-fix records nu, S, R, biases and their variance
    assert seen == [9] and not _mapped(spill_dir) and not list(spill_dir.iterdir())


def _spilled_copy(a: np.ndarray) -> np.ndarray:
    out = spill.empty_rows(a.shape[0], a.shape[1:], a.dtype, spill=True)
    out[:] = a
    return out


def test_plausibility_and_metrics_windows_give_the_whole_arrays_findings(spill_dir):
    from navpp import metrics
    from navpp import plausibility as pl

    n = 5_500
    t = np.arange(n) * 0.01
    alt = np.full(n, 300.0)
    vel = np.zeros((n, 3))
    vel[:, 0] = 20.0
    std = np.ones((n, 3), np.float32)
    fix_alt, fix_su = np.full(10, 300.0), np.full(10, 2.5)
    low, fast, nan_vel, bad = alt.copy(), vel.copy(), vel.copy(), std.copy()
    low[2500:] = -15865.0
    low[4200] = -20000.0                         # the farthest, in a later window
    fast[1700:, 1] = 3e5
    fast[3300, 1] = 4e5
    nan_vel[1200, 0] = np.nan
    bad[4100, 2] = np.inf
    for a, v, s in ((alt, vel, std), (low, vel, std), (alt, fast, std), (alt, nan_vel, std), (alt, fast, bad)):
        for vehicle in ("car", "none"):
            whole = pl.solution_findings("ekf", vehicle, t, a, v, s, fix_alt, fix_su, 0.9999)
            windowed = pl.solution_findings("ekf", vehicle, t, _spilled_copy(a), _spilled_copy(v), _spilled_copy(s),
                                            fix_alt, fix_su, 0.9999)
            assert windowed == whole
    (f,) = pl.solution_findings("ekf", "car", t, low, vel, std, fix_alt, fix_su, 0.9999)
    assert "reaching -2e+04 m" in f.headline
    t_ref = np.linspace(-1.0, t[-1] + 1.0, 3001)
    for y in (low, fast, std):
        br = metrics._Bracket.of(t, t_ref)
        assert np.array_equal(br.linear(_spilled_copy(y)), br.linear(y))
    assert np.array_equal(br.angle_deg(_spilled_copy(low)), br.angle_deg(low))


def test_resampling_a_spilled_solution_gives_the_same_bits(spill_dir):
    rng = np.random.default_rng(5)
    n = 5_500
    cols = {"lat_deg": 45 + rng.normal(0, 1e-4, n), "lon_deg": 7 + rng.normal(0, 1e-4, n),
            "alt": rng.normal(300, 1, n), "vel_enu": rng.normal(0, 5, (n, 3)),
            "rph_deg": rng.uniform(0, 360, (n, 3)), "std_enu": rng.uniform(0, 2, (n, 3)).astype(np.float32),
            "std_att": rng.uniform(0, 1, (n, 3)).astype(np.float32),
            "std_vel_enu": rng.uniform(0, 1, (n, 3)).astype(np.float32), "rate_body": rng.normal(0, 0.1, (n, 3))}
    t = np.arange(n) * 0.008
    kept = Solution(t=t, t0_ns=1_700_000_000_003_000_000, **cols)
    spilled = Solution(t=t, t0_ns=kept.t0_ns, **{k: _spilled_copy(v) for k, v in cols.items()})
    a, b = api.resample_solution(kept, 10.0), api.resample_solution(spilled, 10.0)
    assert all(np.array_equal(v, _arrays(b)[k]) for k, v in _arrays(a).items())


def test_the_compiled_loop_releases_a_spilled_path_behind_it(spill_dir, monkeypatch, tmp_path):
    """The plain EKF's compiled stretches (:mod:`navpp.engine.fused`) write the path rows
    themselves: after each stretch the rows before its last epoch leave memory, as after a
    generic epoch, so the path's resident pages stay near a window and a stretch, far below
    the whole path (sample drive, ~37,500 rows, 3 MB)."""
    from navpp.engine import fused
    from navpp.engine.recorder import RunRecorder

    monkeypatch.setattr(fused, "STRETCH", 40)
    seen: list[tuple[int, int]] = []
    plain = RunRecorder.fused_epochs

    def watched(self, knots, t, sample=-1):
        before = _rss_kb(self.path)
        plain(self, knots, t, sample)
        seen.append((before, _rss_kb(self.path)))
        whole_kb.append(self.path.nbytes // 1024)

    whole_kb: list[int] = []
    monkeypatch.setattr(RunRecorder, "fused_epochs", watched)
    api.process(DRIVE, filter_name="ekf", out_dir=tmp_path / "out", memory=1024)
    assert len(seen) > 20 and whole_kb[-1] > 2500
    assert sum(after < before for before, after in seen) >= 5      # the stretches release, not only generic epochs
    assert max(after for _, after in seen) < whole_kb[-1] // 4


def test_a_spill_that_does_not_fit_is_one_clear_error(spill_dir, monkeypatch):
    """No room for the spill file: one error naming the size, the place and the remedies, at the
    allocation (blocks reserved up front), not a SIGBUS at some later write."""
    from navpp.errors import NavppError

    def full(fd, offset, length):
        raise OSError(28, "No space left on device")

    monkeypatch.setattr(spill.os, "posix_fallocate", full)
    with pytest.raises(NavppError) as err:
        spill.empty_rows(200_000, (10,), np.float64, spill=True)
    msg = str(err.value)
    assert "15 MB" in msg and str(spill_dir) in msg and "No space left" in msg
    assert "TMPDIR" in msg and "--memory" in msg and "\n" not in msg
    assert not _mapped(spill_dir) and not list(spill_dir.iterdir())


def test_release_before_counts_from_the_mapping_for_a_view(spill_dir):
    """A view that starts inside the mapping (the path after the alignment's rows): its rows are
    released by their place in the mapping, a window behind the writer, never ahead of it."""
    a = spill.full_rows(50_000, (10,), 0.0, spill=True)
    view = a[7_000:]
    for i in range(view.shape[0]):
        view[i] = i
        spill.release_before(view, i)
        if i % 5000 == 0:
            assert _rss_kb(a) <= 2 * spill.RELEASE_BYTES // 1024 + 8
    assert np.array_equal(view[:, 0], np.arange(view.shape[0], dtype=float))


def test_the_imu_is_read_onto_the_spill_file_with_the_same_bits(spill_dir):
    """Beyond ``memory`` the CSV reader parses the IMU onto spill files (t, gyro, accel) and
    releases each block behind it and each check's pages after it: the same bits as a read in
    memory, and almost nothing of them resident afterwards."""
    from navpp.io.csv import read_csv_log

    kept = read_csv_log(DRIVE)
    spilled_rec = read_csv_log(DRIVE, memory=1)
    imu0, imu1 = kept.imu, spilled_rec.imu
    assert not spill.spilled(imu0.gyro) and all(spill.spilled(a) for a in (imu1.t, imu1.gyro, imu1.accel))
    assert len(_mapped(spill_dir)) == 3
    assert all(_rss_kb(a) <= 16 for a in (imu1.t, imu1.gyro, imu1.accel))    # released after the last pass
    assert spilled_rec.t0_ns == kept.t0_ns and spilled_rec.warnings == kept.warnings
    assert all(a.dtype == b.dtype and np.array_equal(a, b)
               for a, b in ((imu0.t, imu1.t), (imu0.gyro, imu1.gyro), (imu0.accel, imu1.accel)))
    assert np.array_equal(kept.gnss.t, spilled_rec.gnss.t) and not spill.spilled(spilled_rec.gnss.t)
    del spilled_rec, imu1
    gc.collect()
    assert not _mapped(spill_dir)


def test_a_spilled_parse_that_outgrows_its_guess_keeps_every_row(spill_dir, tmp_path):
    """The parser sizes its arrays from the first 64 KiB's rows; longer rows later make it grow
    them, on the spill file too, rows kept and the same bits as in memory."""
    from navpp.io.csvparse import parse_columns

    rng = np.random.default_rng(3)
    n = 40_000
    t = 1_700_000_000.0 + np.arange(n) * 0.008
    v = rng.normal(0.0, 1.0, (n, 3))
    lines = ["t,a,b,c"]
    for k in range(n):                              # short rows first, then long ones: the guess is short
        fmt = "{:.3f},{:.2f},{:.2f},{:.2f}" if k < 2000 else "{:.3f},{!r},{!r},{!r}"
        lines.append(fmt.format(float(t[k]), *map(float, v[k])))
    path = tmp_path / "grow.csv"
    path.write_text("\n".join(lines) + "\n")
    kept = parse_columns(path, 4, [0, 1, 2, 3], 0, None, [1, 3])
    spilled = parse_columns(path, 4, [0, 1, 2, 3], 0, None, [1, 3], budget_bytes=1)
    assert kept is not None and spilled is not None
    assert spill.spilled(spilled[0][1]) and spilled[0][1].shape == (n, 3)
    for a, b in zip(kept[0], spilled[0]):
        assert np.array_equal(a, b)
    assert np.array_equal(kept[1], spilled[1])


def test_behind_releases_what_a_pass_in_time_order_has_passed(spill_dir):
    """:class:`navpp.spill.Behind` (the filter loop's): rows stamped before the pass's time
    leave memory a window at a time; a pass that starts again releases from its start; the
    values never change; arrays in memory are left alone."""
    n = 20_000
    t = spill.empty_rows(n, (), np.float64, spill=True)
    gyro = spill.empty_rows(n, (3,), np.float64, spill=True)
    t[:] = np.arange(n) * 0.008
    gyro[:] = np.arange(3 * n, dtype=float).reshape(n, 3)
    behind = spill.Behind(t, gyro, np.zeros((n, 3)))
    assert len(behind.arrays) == 2
    before = _rss_kb(gyro)
    for t_s in np.arange(0.0, float(t[-1]), 0.2):
        behind(float(t_s))
    assert _rss_kb(gyro) <= before - 3 * 8 * (n - 2 * spill.WINDOW_ROWS) // 1024
    assert behind.row >= n - 2 * spill.WINDOW_ROWS
    behind(0.1)                                     # another pass from the start
    assert behind.row == 13
    assert np.array_equal(gyro, np.arange(3 * n, dtype=float).reshape(n, 3))
    idle = spill.Behind(np.arange(10.0), np.zeros((10, 3)))
    idle(5.0)
    assert idle.arrays == [] and idle.row == 0


def test_a_parse_that_grows_past_the_budget_goes_onto_the_spill_file(spill_dir, tmp_path):
    """Long rows first make the parser guess too few rows and fit its arrays in the budget; when
    they grow past it, the grown arrays are made on the spill file, with the same bits."""
    from navpp.io.csvparse import parse_columns

    rng = np.random.default_rng(4)
    n = 40_000
    t = 1_700_000_000.0 + np.arange(n) * 0.008
    v = rng.normal(0.0, 1.0, (n, 3))
    lines = ["t,a,b,c"]
    for k in range(n):                              # long rows first: the guess is too few rows
        fmt = "{:.3f},{!r},{!r},{!r}" if k < 2000 else "{:.3f},{:.2f},{:.2f},{:.2f}"
        lines.append(fmt.format(float(t[k]), *map(float, v[k])))
    path = tmp_path / "grow.csv"
    path.write_text("\n".join(lines) + "\n")
    budget = n * 5 * 8 * 3 // 4                     # below what the rows need, above the first guess
    kept = parse_columns(path, 4, [0, 1, 2, 3], 0, None, [1, 3])
    grown = parse_columns(path, 4, [0, 1, 2, 3], 0, None, [1, 3], budget_bytes=budget)
    assert kept is not None and grown is not None
    assert not spill.spilled(kept[0][1])
    assert spill.spilled(grown[0][1]) and grown[0][1].shape == (n, 3)
    for a, b in zip(kept[0], grown[0]):
        assert np.array_equal(a, b)
    assert np.array_equal(kept[1], grown[1])


def test_brackets_in_a_spilled_source_are_found_window_by_window(spill_dir, monkeypatch):
    """metrics._Bracket on a spilled source searches and gathers one window of source rows at a
    time: the same indices, weights and values as on the source in memory, for times in order,
    out of order, repeated, outside the span and NaN, and a source with repeated stamps."""
    from navpp import metrics

    monkeypatch.setattr(spill, "WINDOW_ROWS", 64)
    rng = np.random.default_rng(11)
    n = 1_000
    t_src = np.cumsum(rng.choice([0.0, 0.01, 0.02], n))       # non-decreasing, with repeats
    y = rng.normal(0, 1, (n, 3))
    ordered = np.sort(rng.uniform(t_src[0] - 0.5, t_src[-1] + 0.5, 700))
    shuffled = rng.permutation(np.concatenate([ordered, t_src[::37], [np.nan]]))
    for t in (ordered, shuffled, t_src[[0, 63, 64, 128, n - 1]], np.empty(0)):
        whole = metrics._Bracket.of(t_src, t)
        windowed = metrics._Bracket.of(_spilled_copy(t_src), t)
        for a, b in zip(whole, windowed):
            assert a.dtype == b.dtype and np.array_equal(a, b, equal_nan=True)
        assert np.array_equal(windowed.linear(_spilled_copy(y)), whole.linear(y), equal_nan=True)
        assert np.array_equal(windowed.angle_deg(_spilled_copy(y[:, 2])), whole.angle_deg(y[:, 2]), equal_nan=True)


def test_large_block_mapping_only_where_the_command_allows_it(monkeypatch: pytest.MonkeyPatch) -> None:
    """map_large_blocks leaves the C allocator alone in a program that imports navpp (glibc's
    setting is process-wide and for good); once allowed (the navpp command), it sets glibc's
    mmap threshold to LARGE_BLOCK."""
    import ctypes

    calls: list[tuple[int, int]] = []

    class FakeLibc:
        def mallopt(self, param: ctypes.c_int, value: ctypes.c_int) -> int:
            calls.append((param.value, value.value))
            return 1

    monkeypatch.setattr(spill, "_TRIM", object())          # as on glibc, wherever the test runs
    monkeypatch.setattr(ctypes, "CDLL", lambda name: FakeLibc())
    monkeypatch.setattr(spill, "_LARGE_BLOCKS_ALLOWED", [False])
    spill.map_large_blocks()
    assert calls == []
    spill.allow_large_block_mapping()
    spill.map_large_blocks()
    assert calls == [(-3, spill.LARGE_BLOCK)]
