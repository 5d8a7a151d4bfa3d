"""A CSV file cut short while the fast parser reads it: one error line, never a crash."""

from __future__ import annotations

import numpy as np
import pytest

from navpp.errors import InputError
from navpp.io import csv as csv_reader
from navpp.io import csvparse


def _write(path, rows: int) -> None:
    t = np.arange(rows) * 0.01
    body = "\n".join(f"{x:.6f},0.001,-0.002,0.003,0.1,-0.2,9.81" for x in t)
    path.write_text("t,gx,gy,gz,ax,ay,az\n" + body + "\n")


def test_a_file_cut_short_during_the_parse_is_one_error_line(tmp_path, monkeypatch):
    path = tmp_path / "imu.csv"
    _write(path, 200_000)                        # ~8 MB: more than one 4 MiB block
    real = csvparse._parse_lines
    calls = []

    def cutting(buf, *args):
        out = real(buf, *args)
        if not calls:
            with open(path, "r+b") as fh:        # another process truncates the log
                fh.truncate(path.stat().st_size // 3)
        calls.append(1)
        return out

    monkeypatch.setattr(csvparse, "_parse_lines", cutting)
    with pytest.raises(InputError) as err:
        csv_reader._parse_plain(path, 7, [0, 1, 2, 3, 4, 5, 6], 0, None, [1, 3, 3])
    message = str(err.value)
    assert message.startswith(f"{path}: cannot read: the file got shorter while it was read")
    assert "\n" not in message


def test_a_whole_file_parses_as_before(tmp_path):
    path = tmp_path / "imu.csv"
    _write(path, 200_000)
    values, stamps = csvparse.parse_columns(path, 7, [0, 1, 2, 3, 4, 5, 6], 0, widths=[1, 3, 3])
    assert values[0].shape == (200_000,) and values[2].shape == (200_000, 3)
    np.testing.assert_array_equal(values[0], np.round(np.arange(200_000) * 0.01, 6))
    assert stamps is not None and stamps[-1] == round(199_999 * 0.01 * 1e9)
