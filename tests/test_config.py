"""Tests for navpp.config: presets, unit conversion, TOML loading and every error path."""

from __future__ import annotations

import dataclasses
import math
from pathlib import Path
from types import MappingProxyType

import pytest

from navpp.config import (
    PRESETS,
    Config,
    GnssConfig,
    ImuConfig,
    InitConfig,
    OutputConfig,
    config_from_dict,
    load_config,
)
from navpp.errors import ConfigError

# Oracle: the [imu] preset table of INTERFACES.md, copied by hand.
# (ARW deg/sqrt(h), gyro bias deg/h, gyro instab deg/h, tau s,
#  VRW m/s/sqrt(h), accel bias mg, accel instab mg, tau s)
TABLE = {
    "consumer": (0.5, 200, 10, 100, 0.1, 20, 1, 100),
    "automotive": (1.0, 10, 1, 300, 0.05, 2, 0.1, 300),
    "tactical": (0.1, 1, 0.1, 600, 0.03, 0.3, 0.02, 600),
    "navigation": (0.003, 0.03, 0.01, 3600, 0.03, 0.025, 0.01, 3600),
}
KEYS = (
    "gyro_arw_deg_per_sqrt_h",
    "gyro_bias_deg_per_h",
    "gyro_bias_instability_deg_per_h",
    "gyro_bias_corr_time_s",
    "accel_vrw_mps_per_sqrt_h",
    "accel_bias_mg",
    "accel_bias_instability_mg",
    "accel_bias_corr_time_s",
)


def write(tmp_path: Path, text: str, name: str = "config.toml") -> Path:
    path = tmp_path / name
    path.write_text(text, encoding="utf-8")
    return path


def load_error(tmp_path: Path, text: str) -> str:
    path = write(tmp_path, text)
    with pytest.raises(ConfigError) as info:
        load_config(path)
    message = str(info.value)
    assert message.startswith(str(path)), message  # every message names the file
    return message


# --------------------------------------------------------------------------- presets


def test_presets_match_interfaces_table() -> None:
    assert set(PRESETS) == set(TABLE)
    for name, values in TABLE.items():
        assert PRESETS[name] == dict(zip(KEYS, values, strict=True)), name


@pytest.mark.parametrize("name", list(TABLE))
def test_imu_config_takes_preset_values(name: str) -> None:
    imu = ImuConfig(preset=name)
    assert tuple(getattr(imu, k) for k in KEYS) == TABLE[name]
    assert all(type(getattr(imu, k)) is float for k in KEYS)


def test_preset_from_toml(tmp_path: Path) -> None:
    cfg = load_config(write(tmp_path, '[imu]\npreset = "navigation"\n'))
    assert tuple(getattr(cfg.imu, k) for k in KEYS) == TABLE["navigation"]
    assert any("navigation" in n for n in cfg.notes)


# --------------------------------------------------------------------------- conversions


def test_noise_conversion_hand_computed() -> None:
    imu = ImuConfig(
        gyro_arw_deg_per_sqrt_h=1.0,
        gyro_bias_deg_per_h=10.0,
        gyro_bias_instability_deg_per_h=3.6,
        gyro_bias_corr_time_s=120,
        accel_vrw_mps_per_sqrt_h=0.6,
        accel_bias_mg=2,
        accel_bias_instability_mg=0.5,
        accel_bias_corr_time_s=45.0,
    )
    n = imu.noise()
    assert n.gyro_arw == pytest.approx(math.pi / 180 / 60, rel=1e-12)  # 2.9088821e-4
    assert n.gyro_arw == pytest.approx(2.908882086657216e-4, rel=1e-12)
    assert n.gyro_bias_sigma == pytest.approx(10 * math.pi / 180 / 3600, rel=1e-12)
    assert n.gyro_bias_sigma == pytest.approx(4.84813681109536e-5, rel=1e-12)
    assert n.gyro_bias_instability == pytest.approx(1e-3 * math.pi / 180, rel=1e-12)
    assert n.gyro_bias_tau == 120.0
    assert n.accel_vrw == pytest.approx(0.01, rel=1e-12)
    assert n.accel_bias_sigma == pytest.approx(0.0196133, rel=1e-12)
    assert n.accel_bias_instability == pytest.approx(0.5 * 9.80665e-3, rel=1e-12)
    assert n.accel_bias_tau == 45.0


def test_sample_unit_scales() -> None:
    assert ImuConfig().gyro_scale == 1.0
    assert ImuConfig().accel_scale == 1.0
    imu = ImuConfig(gyro_units="deg/s", accel_units="g")
    assert imu.gyro_scale == pytest.approx(math.pi / 180)
    assert imu.accel_scale == 9.80665


@pytest.mark.parametrize("text", ['"inf"', "inf", '"Infinity"'])
def test_infinite_correlation_time(tmp_path: Path, text: str) -> None:
    cfg = load_config(write(tmp_path, f"[imu]\ngyro_bias_corr_time_s = {text}\n"))
    assert cfg.imu.gyro_bias_corr_time_s == math.inf
    assert cfg.imu.noise().gyro_bias_tau == math.inf


def test_very_large_correlation_time_kept(tmp_path: Path) -> None:
    cfg = load_config(write(tmp_path, "[imu]\naccel_bias_corr_time_s = 1e30\n"))
    assert cfg.imu.accel_bias_corr_time_s == 1e30


# --------------------------------------------------------------------------- overrides


def test_explicit_keys_override_preset(tmp_path: Path) -> None:
    text = '[imu]\npreset = "tactical"\ngyro_arw_deg_per_sqrt_h = 0.2\naccel_bias_mg = 1\n'
    cfg = load_config(write(tmp_path, text))
    expected = dict(zip(KEYS, TABLE["tactical"], strict=True))
    expected.update(gyro_arw_deg_per_sqrt_h=0.2, accel_bias_mg=1.0)
    assert {k: getattr(cfg.imu, k) for k in KEYS} == expected
    assert type(cfg.imu.accel_bias_mg) is float  # int accepted, stored as float
    (note,) = cfg.notes
    assert "tactical" in note and "gyro_arw_deg_per_sqrt_h" in note and "accel_bias_mg" in note


def test_override_without_preset_uses_automotive(tmp_path: Path) -> None:
    cfg = load_config(write(tmp_path, "[imu]\ngyro_bias_deg_per_h = 5\n"))
    assert cfg.imu.preset == "automotive"
    assert cfg.imu.gyro_bias_deg_per_h == 5.0
    assert cfg.imu.gyro_arw_deg_per_sqrt_h == TABLE["automotive"][0]
    assert "automotive" in cfg.notes[0] and "gyro_bias_deg_per_h" in cfg.notes[0]


def test_all_noise_keys_given_note(tmp_path: Path) -> None:
    text = "[imu]\n" + "".join(f"{k} = 1\n" for k in KEYS)
    cfg = load_config(write(tmp_path, text))
    assert all(getattr(cfg.imu, k) == 1.0 for k in KEYS)
    assert "all 8 values" in cfg.notes[0]


# --------------------------------------------------------------------------- defaults


def test_default_config_notes() -> None:
    cfg = Config.default()
    assert cfg == load_config(None)
    assert cfg.source == "built-in defaults"
    assert cfg.notes == ("no config given: using the automotive IMU preset",)
    assert cfg.imu == ImuConfig(preset="automotive")
    assert cfg.gnss.default_std_m == (2.0, 2.0, 4.0)
    assert cfg.output.formats == ("csv",) and cfg.output.rate_hz is None
    assert dict(cfg.filters) == {}


def test_empty_file_notes_default_preset(tmp_path: Path) -> None:
    path = write(tmp_path, "# nothing\n[gnss]\nlever_arm_m = [0.1, 0, 1]\n")
    cfg = load_config(path)
    assert cfg.source == str(path)
    assert cfg.imu.preset == "automotive"
    assert len(cfg.notes) == 1
    assert "automotive" in cfg.notes[0] and "by default" in cfg.notes[0]
    assert cfg.gnss.lever_arm_m == (0.1, 0.0, 1.0)


def test_full_file(tmp_path: Path) -> None:
    text = """
[imu]
preset = "consumer"
mounting_rpy_deg = [180, 0, 90]
gyro_units = "deg/s"
accel_units = "g"
[gnss]
default_vel_std_mps = 0.2
gate_probability = 0
reanchor_after_s = 3.0
time_offset_s = -0.05
[time]
base = "gpst"
source = "log"
[init]
method = "config"
heading_deg = 45
roll_deg = 1.5
[vehicle]
type = "car"
[output]
rate_hz = 10
formats = ["csv", "kml", "csv"]
[filter.rwckf]
seed = 7
window = 20
weights = [1, 2]
[filter.rwckf.extra]
a = 1
"""
    cfg = load_config(write(tmp_path, text))
    assert cfg.imu.mounting_rpy_deg == (180.0, 0.0, 90.0)
    assert cfg.gnss.gate_probability == 0.0
    assert cfg.gnss.reanchor_after_s == 3.0
    assert cfg.time == dataclasses.replace(cfg.time, base="gpst", source="log")
    assert cfg.init.method == "config" and cfg.init.heading_deg == 45.0
    assert cfg.init.roll_deg == 1.5 and cfg.init.pitch_deg is None
    assert cfg.vehicle.type == "car"
    assert cfg.output.rate_hz == 10.0 and cfg.output.formats == ("csv", "kml")
    rw = cfg.filters["rwckf"]
    assert rw["seed"] == 7 and rw["weights"] == (1, 2) and rw["extra"]["a"] == 1
    assert isinstance(cfg.filters, MappingProxyType) and isinstance(rw, MappingProxyType)
    with pytest.raises(TypeError):
        rw["seed"] = 8  # type: ignore[index]
    with pytest.raises(dataclasses.FrozenInstanceError):
        cfg.imu.preset = "tactical"  # type: ignore[misc]


def test_formats_as_comma_string() -> None:
    assert OutputConfig(formats="csv, mcap").formats == ("csv", "mcap")  # type: ignore[arg-type]


@pytest.mark.parametrize(
    ("value", "expected"),
    [(3, (3.0, 3.0, 3.0)), (1.5, (1.5, 1.5, 1.5)), ([1, 2.5], (1.0, 1.0, 2.5)),
     ([1, 2, 3], (1.0, 2.0, 3.0))],
)
def test_default_std_m_shapes(tmp_path: Path, value: object, expected: tuple[float, ...]) -> None:
    toml_value = str(value).replace("'", '"')
    cfg = load_config(write(tmp_path, f"[gnss]\ndefault_std_m = {toml_value}\n"))
    assert cfg.gnss.default_std_m == expected
    assert all(type(v) is float for v in cfg.gnss.default_std_m)


def test_config_from_dict_direct() -> None:
    cfg = config_from_dict({"imu": {"preset": "tactical"}}, "inline")
    assert cfg.source == "inline" and cfg.imu.preset == "tactical"


# --------------------------------------------------------------------------- errors


def test_unknown_key_suggests_nearest(tmp_path: Path) -> None:
    msg = load_error(tmp_path, "[imu]\ngyro_arw = 1\n")
    assert msg == (
        f"{tmp_path / 'config.toml'}: unknown key 'gyro_arw' in [imu]; "
        "did you mean 'gyro_arw_deg_per_sqrt_h'?"
    )


@pytest.mark.parametrize(
    ("text", "wanted"),
    [
        ("[imu]\naccel_bias_instabilty_mg = 1\n", ["[imu]", "'accel_bias_instability_mg'"]),
        ("[gnss]\nlever_arm = [0, 0, 1]\n", ["[gnss]", "'lever_arm_m'"]),
        ("[gnss]\ngate_prob = 0.99\n", ["[gnss]", "'gate_probability'"]),
        ("[time]\nbasis = 'unix'\n", ["[time]", "'base'"]),
        ("[init]\nheading = 3\n", ["[init]", "'heading_deg'"]),
        ("[vehicle]\ntyp = 'car'\n", ["[vehicle]", "'type'"]),
        ("[output]\nformat = ['csv']\n", ["[output]", "'formats'"]),
        ("[output]\nrate = 10\n", ["[output]", "'rate_hz'"]),
    ],
)
def test_unknown_keys_every_section(tmp_path: Path, text: str, wanted: list[str]) -> None:
    msg = load_error(tmp_path, text)
    assert "unknown key" in msg and "did you mean" in msg
    for w in wanted:
        assert w in msg


def test_unknown_key_without_close_match_lists_valid(tmp_path: Path) -> None:
    msg = load_error(tmp_path, "[vehicle]\nzzzzzz = 1\n")
    assert "'zzzzzz'" in msg and "valid keys: type" in msg


def test_unknown_section(tmp_path: Path) -> None:
    msg = load_error(tmp_path, "[gnns]\nlever_arm_m = [0, 0, 0]\n")
    assert "unknown section [gnns]" in msg and "did you mean [gnss]?" in msg
    msg = load_error(tmp_path, "[filters.ekf]\nseed = 1\n")
    assert "did you mean [filter]?" in msg


def test_key_outside_section(tmp_path: Path) -> None:
    msg = load_error(tmp_path, 'preset = "tactical"\n')
    assert "'preset'" in msg and "[imu]" in msg


def test_filter_section_must_hold_tables(tmp_path: Path) -> None:
    msg = load_error(tmp_path, "[filter]\nseed = 1\n")
    assert "[filter]" in msg and "'seed'" in msg


@pytest.mark.parametrize(
    ("text", "key", "shown"),
    [
        ('[imu]\ngyro_arw_deg_per_sqrt_h = "1.0"\n', "gyro_arw_deg_per_sqrt_h", "'1.0'"),
        ("[imu]\naccel_bias_mg = true\n", "accel_bias_mg", "True"),
        ("[imu]\nmounting_rpy_deg = [0, 0]\n", "mounting_rpy_deg", "[0, 0]"),
        ('[imu]\nmounting_rpy_deg = [0, 0, "x"]\n', "mounting_rpy_deg", "'x'"),
        ("[gnss]\nlever_arm_m = 1.0\n", "lever_arm_m", "1.0"),
        ("[gnss]\nlever_arm_m = [1, 2, 3, 4]\n", "lever_arm_m", "[1, 2, 3, 4]"),
        ("[gnss]\ndefault_std_m = [1, 2, 3, 4]\n", "default_std_m", "[1, 2, 3, 4]"),
        ('[gnss]\ndefault_std_m = "2"\n', "default_std_m", "'2'"),
        ("[gnss]\ndefault_vel_std_mps = false\n", "default_vel_std_mps", "False"),
        ('[gnss]\nreanchor_after_s = "10"\n', "reanchor_after_s", "'10'"),
        ('[gnss]\ntime_offset_s = "0.1"\n', "time_offset_s", "'0.1'"),
        ("[imu]\ngyro_bias_deg_per_h = nan\n", "gyro_bias_deg_per_h", "nan"),
        ('[init]\nheading_deg = "north"\n', "heading_deg", "'north'"),
        ('[output]\nrate_hz = "10"\n', "rate_hz", "'10'"),
        ("[output]\nformats = []\n", "formats", "[]"),
        ("[imu]\ngyro_bias_corr_time_s = -inf\n", "gyro_bias_corr_time_s", "-inf"),
        ('[imu]\ngyro_bias_corr_time_s = "forever"\n', "gyro_bias_corr_time_s", "'forever'"),
    ],
)
def test_wrong_types(tmp_path: Path, text: str, key: str, shown: str) -> None:
    msg = load_error(tmp_path, text)
    assert key in msg and shown in msg


def test_section_not_a_table(tmp_path: Path) -> None:
    with pytest.raises(ConfigError, match=r"src: \[imu\] must be a table, got 3"):
        config_from_dict({"imu": 3}, "src")


@pytest.mark.parametrize("key", [k for k in KEYS if not k.endswith("corr_time_s")])
def test_negative_noise_rejected(tmp_path: Path, key: str) -> None:
    msg = load_error(tmp_path, f"[imu]\n{key} = -0.5\n")
    assert key in msg and ">= 0" in msg and "-0.5" in msg


@pytest.mark.parametrize("value", ["0", "-10", "0.0"])
@pytest.mark.parametrize("key", ["gyro_bias_corr_time_s", "accel_bias_corr_time_s"])
def test_non_positive_corr_time_rejected(tmp_path: Path, key: str, value: str) -> None:
    msg = load_error(tmp_path, f"[imu]\n{key} = {value}\n")
    assert key in msg and "> 0" in msg


@pytest.mark.parametrize(
    ("text", "key"),
    [
        ("[gnss]\ndefault_std_m = 0\n", "default_std_m"),
        ("[gnss]\ndefault_std_m = [1, -1]\n", "default_std_m"),
        ("[gnss]\ndefault_vel_std_mps = 0\n", "default_vel_std_mps"),
        ("[gnss]\ngate_probability = 1.0\n", "gate_probability"),
        ("[gnss]\ngate_probability = -0.1\n", "gate_probability"),
        ("[gnss]\nreanchor_after_s = 0\n", "reanchor_after_s"),
        ("[init]\npitch_deg = 95\n", "pitch_deg"),
        ("[init]\ngyrocompass_max_heading_std_deg = 0\n", "gyrocompass_max_heading_std_deg"),
        ("[output]\nrate_hz = 0\n", "rate_hz"),
    ],
)
def test_out_of_range(tmp_path: Path, text: str, key: str) -> None:
    assert key in load_error(tmp_path, text)


def test_unknown_preset_lists_valid(tmp_path: Path) -> None:
    msg = load_error(tmp_path, '[imu]\npreset = "marine"\n')
    assert "'marine'" in msg
    for name in TABLE:
        assert repr(name) in msg


def test_misspelt_preset_suggests(tmp_path: Path) -> None:
    msg = load_error(tmp_path, '[imu]\npreset = "tactcal"\n')
    assert "did you mean 'tactical'?" in msg


@pytest.mark.parametrize(
    ("text", "key", "valid"),
    [
        ('[imu]\ngyro_units = "deg/sec"\n', "gyro_units", ["'rad/s'", "'deg/s'"]),
        ('[imu]\naccel_units = "m/s2"\n', "accel_units", ["'m/s^2'", "'g'"]),
        ('[time]\nbase = "utc"\n', "base", ["'unix'", "'gpst'", "'relative'"]),
        ('[time]\nsource = "bag"\n', "source", ["'header'", "'log'"]),
        ('[init]\nmethod = "magic"\n', "method", ["'auto'", "'gyrocompass'", "'gnss'", "'config'"]),
        ('[vehicle]\ntype = "boat"\n', "type", ["'car'", "'none'"]),
        ('[output]\nformats = ["csv", "gpx"]\n', "formats", ["'csv'", "'mcap'", "'tum'",
                                                           "'geojson'", "'kml'"]),
    ],
)
def test_unknown_enum_lists_values(tmp_path: Path, text: str, key: str, valid: list[str]) -> None:
    msg = load_error(tmp_path, text)
    assert key in msg
    for v in valid:
        assert v in msg


def test_init_config_method_requires_heading(tmp_path: Path) -> None:
    msg = load_error(tmp_path, '[init]\nmethod = "config"\nroll_deg = 0\n')
    assert "heading_deg" in msg
    with pytest.raises(ConfigError, match="heading_deg"):
        InitConfig(method="config")


def test_toml_syntax_error_has_line_and_column(tmp_path: Path) -> None:
    msg = load_error(tmp_path, '[imu]\npreset = "tactical"\ngyro_arw_deg_per_sqrt_h = = 1\n')
    assert "invalid TOML" in msg and "line 3" in msg and "column" in msg


def test_missing_file_names_path(tmp_path: Path) -> None:
    path = tmp_path / "nope.toml"
    with pytest.raises(ConfigError, match="not found") as info:
        load_config(path)
    assert str(path) in str(info.value)


def test_directory_is_not_a_config(tmp_path: Path) -> None:
    with pytest.raises(ConfigError) as info:
        load_config(tmp_path)
    assert str(tmp_path) in str(info.value)


def test_non_utf8_file(tmp_path: Path) -> None:
    path = tmp_path / "config.toml"
    path.write_bytes(b"[imu]\npreset = \"\xff\"\n")
    with pytest.raises(ConfigError, match="UTF-8"):
        load_config(path)


def test_python_construction_is_validated() -> None:
    with pytest.raises(ConfigError, match="gyro_arw_deg_per_sqrt_h"):
        ImuConfig(gyro_arw_deg_per_sqrt_h=-1.0)
    with pytest.raises(ConfigError, match="nan"):
        ImuConfig(accel_bias_mg=float("nan"))
    with pytest.raises(ConfigError, match="lever_arm_m"):
        GnssConfig(lever_arm_m=(0.0, 0.0))  # type: ignore[arg-type]
    assert GnssConfig(default_std_m=[1, 2]).default_std_m == (1.0, 1.0, 2.0)  # type: ignore[arg-type]


def test_imu_ranges_are_optional_and_positive() -> None:
    cfg = config_from_dict({"imu": {"gyro_range_rps": 34.9, "accel_range_mps2": 156.9}}, "test")
    assert (cfg.imu.gyro_range_rps, cfg.imu.accel_range_mps2) == (34.9, 156.9)
    assert config_from_dict({}, "test").imu.gyro_range_rps is None
    with pytest.raises(ConfigError, match=r"\[imu\] accel_range_mps2"):
        config_from_dict({"imu": {"accel_range_mps2": 0.0}}, "test")
