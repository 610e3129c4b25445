"""The lab setup: the shipped reference setup, validation with key paths, round trips."""

import dataclasses
import json

import pytest

from rig.config.setup import ChannelSetup, LabSetup, load_setup, setup_from_dict
from rig.config.tomlconfig import ConfigError


@pytest.fixture(scope="module")
def reference():
    return load_setup("reference")


def test_reference_setup_is_the_papers_rig(reference):
    drive = reference.drive_force_channel
    assert (reference.drive.point, drive.point, drive.quantity) == (3, 3, "force")
    assert drive.sensitivity_unit == "mV/N" and drive.serial and drive.calibration_date
    head_acc = [c for c in reference.channels if c.role == "drive-acceleration"]
    assert [(c.point, c.serial) for c in head_acc] == [(3, drive.serial)]
    accels = [c for c in reference.channels if c.role == "response"]
    assert sorted(c.point for c in accels) == [1, 2, 4, 5, 6, 7, 8, 9, 10, 11, 12, 13]
    for c in accels:  # PCB 352A56-class: about 10 mV/g, 5.5 g
        assert 9.0 < c.sensitivity < 11.0 and c.sensitivity_unit == "mV/g"
        assert c.mass_kg == pytest.approx(0.0055)
        assert c.direction == ("x" if c.point in (8, 9, 12, 13) else "y")
    assert reference.points == tuple(range(1, 14))
    assert reference.amplifier.port == ""


def test_channel_selection_for_the_paper_points(reference):
    chans = reference.channels_for_points([3, 6, 7])
    assert [c.name for c in chans] == ["force3", "acc3", "acc6", "acc7"]
    config = reference.acquisition_config(chans, 5120.0)
    assert config.sample_rate_hz == 5120.0 and config.ao.limit_v == reference.drive.limit_v
    assert [a.name for a in config.ai] == ["force3", "acc3", "acc6", "acc7"]
    infos = [c.channel_info() for c in chans]
    assert [i.role for i in infos] == ["drive-force", "drive-acceleration", "response", "response"]
    assert infos[0].unit == "N" and infos[2].unit == "m/s^2"
    with pytest.raises(ValueError, match=r"no accelerometer at point\(s\) \[14\]"):
        reference.channels_for_points([3, 14])


def test_range_in_channel_units(reference):
    acc7 = next(c for c in reference.channels if c.name == "acc7")
    assert acc7.range_units == pytest.approx(5.0 / (acc7.sensitivity / 1000) * 9.80665)


def test_round_trip_through_json(reference):
    again = setup_from_dict(json.loads(json.dumps(reference.to_dict())))
    assert again == reference


def _table(reference):
    return json.loads(json.dumps(reference.to_dict()))


@pytest.mark.parametrize(
    "change, key",
    [
        (lambda d: d["channels"][2].update(sensitivity=-1.0), "channels[2]"),
        (lambda d: d["channels"][3].update(sensitivty=10.0), "channels[3]"),
        (lambda d: d["channels"][0].update(sensitivity_unit="mV/g"), "channels[0]"),
        (lambda d: d["daq"].update(sample_rate_hz="fast"), "daq.sample_rate_hz"),
        (lambda d: d["drive"].pop("physical"), "drive.physical"),
        (lambda d: d["channels"][4].update(calibration_date="last May"), "channels[4]"),
        (lambda d: d.update(colour="blue"), "(root)"),
    ],
)
def test_errors_name_the_key(reference, change, key):
    data = _table(reference)
    change(data)
    with pytest.raises(ConfigError) as err:
        setup_from_dict(data, "setup test.toml")
    assert f"setup test.toml: {key}" in str(err.value)


def test_setup_level_rules(reference):
    data = _table(reference)
    data["channels"][3]["name"] = "acc3"
    with pytest.raises(ConfigError, match="duplicate channel names"):
        setup_from_dict(data)
    data = _table(reference)
    data["channels"][0]["role"] = "response"
    with pytest.raises(ConfigError, match="exactly one channel of role 'drive-force'"):
        setup_from_dict(data)
    drive = reference.drive_force_channel
    with pytest.raises(ValueError, match="drive at point 5"):
        LabSetup(
            name="x",
            drive=dataclasses.replace(reference.drive, point=5),
            channels=reference.channels,
        )
    with pytest.raises(ConfigError, match="ChannelSetup.direction: expected x, y or z") as err:
        ChannelSetup(
            name="f",
            physical="Dev1/ai0",
            quantity="force",
            point=3,
            direction="q",
            sensitivity=1.0,
            sensitivity_unit="mV/N",
        )
    assert err.value.path == ("direction",)
    assert drive.role == "drive-force"


def test_setup_file_and_unknown_name(tmp_path, reference):
    import tomli_w

    data = _table(reference)
    data["daq"]["sample_rate_hz"] = 10240.0
    path = tmp_path / "lab.toml"
    path.write_bytes(tomli_w.dumps(data).encode())
    assert load_setup(path).daq.sample_rate_hz == 10240.0
    with pytest.raises(ConfigError, match="not a built-in setup .*reference"):
        load_setup("nonexistent")
    path.write_text("name = [")
    with pytest.raises(ConfigError, match="not valid TOML"):
        load_setup(path)
