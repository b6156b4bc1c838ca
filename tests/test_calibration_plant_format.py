"""The plant file's format 3 (intervals, identified top drive with an optional pipe) and the
format-1 and format-2 files it still reads."""

from __future__ import annotations

import dataclasses
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


def test_format_3_round_trip_with_intervals_and_top_drive(tmp_path: Path) -> None:
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


def test_format_2_files_are_still_read(tmp_path: Path) -> None:
    data = _plant().to_json()
    data["format"] = "drill-string-gym/calibrated-plant/2"
    (tmp_path / "two.json").write_text(json.dumps(data))
    plant = load_plant(tmp_path / "two.json")
    assert plant.top_drive == TOP_DRIVE
    assert drill_string_parameters(plant).J_pi == pytest.approx(0.05 * 0.02)


def test_an_identified_pipe_is_the_4dof_pipe(tmp_path: Path) -> None:
    """A plant with a pipe keeps it in the 4-DOF map; the bit-side spring's compliance is
    kept (two springs of 2 k in series)."""
    pipe = {
        **TOP_DRIVE,
        "damping_nm_s_rad": 0.002,
        "pipe_inertia_kg_m2": 0.06,
        "pipe_stiffness_nm_rad": 8.0,
        "pipe_damping_nm_s_rad": 0.004,
    }
    plant = dataclasses.replace(_plant(), top_drive=pipe)
    again = load_plant(plant.save(tmp_path / "plant.json"))
    params = drill_string_parameters(again)
    assert (params.J_pi, params.k_pi, params.c_pi) == pytest.approx((0.06, 8.0, 0.004))
    assert params.c_dt == pytest.approx(0.002)
    assert 1 / (1 / params.k_co + 1 / params.k_bi) == pytest.approx(VALUES["stiffness"])


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
