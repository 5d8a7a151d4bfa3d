"""Issue 21 point 1 (``process`` memory): the IMU-rate output steps make their result and no
temporaries as long as the log, with the same figures to the last bit as the vectorised forms
they replace (body rate, noise profile, trajectory.csv)."""

from __future__ import annotations

import tracemalloc

import numpy as np
import pytest

from navpp.engine.output import body_rate
from navpp.geodesy import OMEGA_E, radii
from navpp.ins import calibrate
from navpp.io import writers
from navpp.recording import Solution


def _path(n: int, seed: int = 4) -> np.ndarray:
    """Recorded rows (n, 10): q_nb (unit), vel_enu m/s, lat rad, lon rad, h m."""
    rng = np.random.default_rng(seed)
    q = rng.normal(size=(n, 4))
    q /= np.linalg.norm(q, axis=1, keepdims=True)
    lat = np.radians(rng.uniform(-80.0, 80.0, n))
    return np.column_stack([q, rng.normal(0, 20, (n, 3)), lat, np.zeros(n), rng.normal(300, 50, n)])


def _body_rate_vectorised(t, path, gyro, bias_t, bias_gyro, bias0):
    """The numpy form body_rate had before it was compiled: (N, 3, 3) DCMs and an einsum."""
    k = np.searchsorted(bias_t, t, side="right") - 1
    bg = np.where((k >= 0)[:, None], bias_gyro[np.maximum(k, 0)], bias0[None, :])
    w, x, y, z = (path[:, i] for i in range(4))
    lat, h, ve, vn = path[:, 7], path[:, 9], path[:, 4], path[:, 5]
    rm, rn = radii(lat)
    w_in = np.column_stack([-vn / (rm + h), OMEGA_E * np.cos(lat) + ve / (rn + h),
                            OMEGA_E * np.sin(lat) + ve * np.tan(lat) / (rn + h)])
    c = np.empty((t.shape[0], 3, 3))
    c[:, 0] = np.column_stack([1.0 - 2.0 * (y * y + z * z), 2.0 * (x * y - w * z), 2.0 * (x * z + w * y)])
    c[:, 1] = np.column_stack([2.0 * (x * y + w * z), 1.0 - 2.0 * (x * x + z * z), 2.0 * (y * z - w * x)])
    c[:, 2] = np.column_stack([2.0 * (x * z - w * y), 2.0 * (y * z + w * x), 1.0 - 2.0 * (x * x + y * y)])
    return gyro - bg - np.einsum("nji,nj->ni", c, w_in)


def test_body_rate_is_the_vectorised_form_to_the_last_bit():
    n = 2000
    rng = np.random.default_rng(7)
    path = _path(n)
    t = np.arange(n) * 0.008
    gyro = rng.normal(0, 0.3, (n, 3))
    bias_t = np.array([1.0, 1.0, 5.2, 9.0, 30.0])       # a repeated stamp; the last beyond the samples
    bias_gyro, bias0 = rng.normal(0, 1e-3, (5, 3)), rng.normal(0, 1e-3, 3)
    got = body_rate(t, path, gyro, bias_t, bias_gyro, bias0)
    assert got.shape == (n, 3) and got.dtype == np.float64
    assert np.array_equal(got, _body_rate_vectorised(t, path, gyro, bias_t, bias_gyro, bias0))


def test_body_rate_makes_no_temporary_as_long_as_the_log():
    n = 200_000
    path, t, gyro = _path(n), np.arange(n) * 0.008, np.zeros((n, 3))
    bias_t, bias_gyro = t[::25].copy(), gyro[::25].copy()
    body_rate(t[:10], path[:10], gyro[:10], bias_t[:1], bias_gyro[:1], gyro[0])   # compiled before the count
    tracemalloc.start()
    try:
        body_rate(t, path, gyro, bias_t, bias_gyro, gyro[0])
        _, peak = tracemalloc.get_traced_memory()
    finally:
        tracemalloc.stop()
    assert peak < n * 3 * 8 + 1_000_000      # the (N, 3) result, nothing of its size besides


def test_noise_profile_top_band_in_parts_is_the_whole_log_at_once(monkeypatch):
    rng = np.random.default_rng(2)
    w, nb = 120, 23
    xb = rng.normal(0, 1e-3, (w * nb, 3))
    xb[w * 7 + 3, 1] = 4.0                  # a glitch
    xb[w * 11, 2] = np.nan
    kernel = np.ones(calibrate.NOISE_SPAN) / calibrate.NOISE_SPAN
    res = np.column_stack([xb[:, j] - np.convolve(xb[:, j], kernel, mode="same") for j in range(3)])
    whole = calibrate._row_sums(res.reshape(nb, w * 3))
    for blocks in (1, 4, 5, 23, 512):
        monkeypatch.setattr(calibrate, "_TOP_CHUNK_BLOCKS", blocks)
        parts = calibrate._top_row_sums(xb, w, nb)
        assert all(np.array_equal(a, b) for a, b in zip(parts, whole)), blocks


@pytest.mark.parametrize("chunk", [7, writers._CHUNK_ROWS])
def test_trajectory_csv_of_float32_columns_is_their_float64_copy(tmp_path, monkeypatch, chunk):
    """The float32 1-sigma is widened block by block as it is written: the same bytes as a
    solution holding its float64 copy."""
    monkeypatch.setattr(writers, "_CHUNK_ROWS", chunk)
    n = 50
    rng = np.random.default_rng(3)
    std32 = rng.uniform(0.01, 5.0, (n, 3)).astype(np.float32)
    std32[4, 1] = np.nan

    def sol(std: np.ndarray) -> Solution:
        return Solution(t=np.arange(n) * 0.008, lat_deg=rng.uniform(-80, 80, n), lon_deg=rng.uniform(-180, 180, n),
                        alt=rng.normal(300, 50, n), vel_enu=rng.normal(0, 10, (n, 3)),
                        rph_deg=rng.uniform(-180, 180, (n, 3)).astype(np.float32), std_enu=std, t0_ns=0)

    state = rng.bit_generator.state
    writers.write_trajectory_csv(tmp_path / "a.csv", sol(std32), t0_s=1.7e9)
    rng.bit_generator.state = state
    writers.write_trajectory_csv(tmp_path / "b.csv", sol(std32.astype(np.float64)), t0_s=1.7e9)
    assert (tmp_path / "a.csv").read_bytes() == (tmp_path / "b.csv").read_bytes()


def test_block_statistics_in_parts_are_the_whole_log_at_once(monkeypatch):
    rng = np.random.default_rng(5)
    n = 125 * 47 + 17
    t = np.arange(n) / 125.0
    gyro, accel = rng.normal(0, 1e-2, (n, 3)), rng.normal(0, 0.1, (n, 3)) + [0.0, 0.0, 9.8]
    monkeypatch.setattr(calibrate, "_STAT_CHUNK_BLOCKS", 10 ** 6)
    whole = calibrate.block_statistics(t, gyro, accel)
    for blocks in (1, 5, whole.nb - 1):       # the last part a single block, then two parts
        monkeypatch.setattr(calibrate, "_STAT_CHUNK_BLOCKS", blocks)
        parts = calibrate.block_statistics(t, gyro, accel)
        assert all(np.array_equal(getattr(parts, k), getattr(whole, k))
                   for k in ("gyro_mean", "gyro_std", "gyro_lp", "accel_mean", "accel_std", "accel_lp")), blocks
