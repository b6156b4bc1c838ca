"""The plant file's format 2 (intervals, identified top drive) and the format-1 files it
still reads."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from drill_env.calibrated_plant import (
    PLANT_FORMAT,
    READ_FORMATS,
    CalibratedPlant,
    FittedParameter,
    drill_string_parameters,
    load_plant,
    parameter_unit,
)

VALUES = {
    "bit_inertia": 0.02,
    "stiffness": 1.5,
    "damping": 0.01,
    "static_friction": 2.5,
    "sliding_friction": 1.5,
    "stribeck_rate": 0.5,
}
TOP_DRIVE = {
    "inertia_kg_m2": 0.08,
    "speed_gain_nm_s_rad": 0.6,
    "integral_gain_nm_rad": 1.5,
    "reference_speed_rad_s": 3.0,
}


def _plant() -> CalibratedPlant:
    return CalibratedPlant(
        "karnopp",
        False,
        {
            n: FittedParameter(v, parameter_unit(n, False), True, 0.01, "", (0.99 * v, 1.01 * v))
            for n, v in VALUES.items()
        },
        top_drive=TOP_DRIVE,
    )


def test_format_2_round_trip_with_intervals_and_top_drive(tmp_path: Path) -> None:
    plant = _plant()
    path = plant.save(tmp_path / "plant.json")
    data = json.loads(path.read_text())
    assert data["format"] == PLANT_FORMAT == READ_FORMATS[-1]
    assert data["parameters"]["stiffness"]["interval_95"] == pytest.approx([1.485, 1.515])
    again = load_plant(path)
    assert again.parameters["stiffness"].interval_95 == pytest.approx((1.485, 1.515))
    assert again.top_drive == TOP_DRIVE
    assert drill_string_parameters(again).J_dt == pytest.approx(0.08)


def test_format_1_files_are_still_read(tmp_path: Path) -> None:
    data = _plant().to_json()
    data["format"] = "drill-string-gym/calibrated-plant/1"
    for entry in data["parameters"].values():
        del entry["interval_95"]
    data["top_drive"] = None
    (tmp_path / "old.json").write_text(json.dumps(data))
    plant = load_plant(tmp_path / "old.json")
    assert plant.parameters["bit_inertia"].interval_95 is None
    assert plant.top_drive is None


@pytest.mark.parametrize(
    ("interval", "fmt"),
    [([2.0, 1.0], None), ([1.0], None), (["a", 1.0], None), (None, "drill-string-gym/other/9")],
)
def test_bad_intervals_and_formats_are_refused(
    tmp_path: Path, interval: object, fmt: str | None
) -> None:
    data = _plant().to_json()
    data["parameters"]["stiffness"]["interval_95"] = interval
    if fmt is not None:
        data["format"] = fmt
    (tmp_path / "bad.json").write_text(json.dumps(data))
    with pytest.raises(ValueError, match="interval_95" if fmt is None else "format"):
        load_plant(tmp_path / "bad.json")
