"""Model and checkpoint files from others: hostile payloads in every slot a loader reads.

Each payload would create a marker file if it were ever unpickled or executed; every load
must fail with a one-line ``ValueError``/``FileNotFoundError`` naming the file and what is
wrong, and the marker must never appear. Both formats are attacked: today's (safetensors,
the shipped models) and the previous one (``.npz``, the copies in ``tests/data/format2``).
Also: the shipped models are the format-2 models converted bit for bit, the trust a user
grants a pickle covers exactly the file named, the shipped agent against a torch forward pass
and an SB3 model of its weights, built here, and loading and evaluating it in a Python where
torch and Stable-Baselines3 cannot be imported.
"""

from __future__ import annotations

import base64
import dataclasses
import io
import json
import os
import pickle
import re
import shlex
import shutil
import subprocess
import sys
import zipfile
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

import gymnasium as gym
import numpy as np
import pytest
import safetensors.numpy

import drill_env  # noqa: F401
from agents import DEFAULT_MODEL_DIR, load_policy
from agents.convert import convert_model
from drill_env.evaluation import rollout
from experiments.cli import main as cli_main

SHIPPED = DEFAULT_MODEL_DIR / "residual_ppo"
ROOT = Path(__file__).resolve().parents[1]
FORMAT2 = ROOT / "tests" / "data" / "format2"
"""The shipped models as they were in the previous format (``.npz`` arrays), before the
conversion."""
SHIPPED_NAMES = ("residual_ppo", "direct_ppo", "field_agent")
CONVERTED_NAMES = ("residual_ppo", "direct_ppo")
"""The shipped models converted from the previous format (the field agent shipped since was
written in format 3 by ``drill-gym train``; its format-2 predecessor stays in ``FORMAT2``)."""


class _Payload:
    """Unpickling this runs ``touch MARKER``."""

    def __init__(self, marker: Path) -> None:
        self.marker = marker

    def __reduce__(self) -> tuple[Any, tuple[str]]:
        return (os.system, (f"touch {shlex.quote(str(self.marker))}",))


@pytest.fixture
def marker(tmp_path: Path) -> Iterator[Path]:
    """The marker file; it must not exist after the test."""
    path = tmp_path / "MARKER"
    yield path
    assert not path.exists(), "a payload was executed"


def payload(marker: Path) -> bytes:
    return pickle.dumps(_Payload(marker))


def test_the_payload_is_live(tmp_path: Path) -> None:
    """Unpickled, the payload does create the marker: the tests below can fail."""
    path = tmp_path / "MARKER"
    pickle.loads(payload(path))  # noqa: S301 - the point of the test
    assert path.exists()


def model_copy(tmp_path: Path, source: Path = SHIPPED) -> Path:
    folder = tmp_path / "model"
    shutil.copytree(source, folder)
    return folder


def _edit_config(edit: Callable[[dict[str, Any]], None]) -> Callable[[Path, bytes], None]:
    def mutate(folder: Path, evil: bytes) -> None:
        record = json.loads((folder / "config.json").read_text())
        edit(record)
        (folder / "config.json").write_text(json.dumps(record))

    return mutate


def _config_text(change: Callable[[str, bytes], str]) -> Callable[[Path, bytes], None]:
    def mutate(folder: Path, evil: bytes) -> None:
        text = (folder / "config.json").read_text()
        (folder / "config.json").write_text(change(text, evil))

    return mutate


def _serialized(evil: bytes) -> dict[str, str]:
    return {":type:": "<class 'abc.ABCMeta'>", ":serialized:": base64.b64encode(evil).decode()}


def _set(path: tuple[Any, ...], value: Any) -> Callable[[dict[str, Any]], None]:
    def edit(record: dict[str, Any]) -> None:
        target: Any = record
        for key in path[:-1]:
            target = target[key]
        target[path[-1]] = value

    return edit


def _weights(folder: Path) -> dict[str, np.ndarray]:
    with np.load(folder / "policy.npz") as data:
        return {k: data[k] for k in data.files}


def _norm(folder: Path) -> dict[str, np.ndarray]:
    with np.load(folder / "obs_norm.npz") as data:
        return {k: data[k] for k in data.files}


def _save_arrays(name: str, change: Callable[[dict[str, Any], bytes, Path], None]) -> Any:
    def mutate(folder: Path, evil: bytes) -> None:
        arrays: dict[str, Any] = _weights(folder) if name == "policy.npz" else _norm(folder)
        change(arrays, evil, folder)
        np.savez(folder / name, **arrays)  # type: ignore[arg-type]

    return mutate


def _raw(name: str, make: Callable[[Path, bytes], bytes]) -> Callable[[Path, bytes], None]:
    def mutate(folder: Path, evil: bytes) -> None:
        (folder / name).write_bytes(make(folder, evil))

    return mutate


def _zip_entries(entries: list[tuple[str, bytes, int]]) -> bytes:
    buffer = io.BytesIO()
    with zipfile.ZipFile(buffer, "w") as archive:
        for name, data, compression in entries:
            archive.writestr(zipfile.ZipInfo(name), data, compress_type=compression)
    return buffer.getvalue()


def _npy(array: np.ndarray) -> bytes:
    buffer = io.BytesIO()
    np.save(buffer, array, allow_pickle=True)
    return buffer.getvalue()


def _npy_header_only(shape: tuple[int, ...], descr: str = "<f8") -> bytes:
    buffer = io.BytesIO()
    np.lib.format.write_array_header_1_0(
        buffer, {"descr": descr, "fortran_order": False, "shape": shape}
    )
    return buffer.getvalue()


def _valid_entries(folder: Path, name: str) -> list[tuple[str, bytes, int]]:
    arrays = _weights(folder) if name == "policy.npz" else _norm(folder)
    return [(k + ".npy", _npy(v), zipfile.ZIP_STORED) for k, v in arrays.items()]


def _replace_entry(name: str, entry: str, data: bytes, compression: int = 0, drop: str = "") -> Any:
    def make(folder: Path, evil: bytes) -> bytes:
        entries = [e for e in _valid_entries(folder, name) if e[0] not in (entry, drop)]
        return _zip_entries([*entries, (entry, data, compression)])

    return _raw(name, make)


def _zip_bomb(folder: Path, evil: bytes) -> bytes:
    entries = _valid_entries(folder, "policy.npz")
    bomb = _npy_header_only((64, 11)) + bytes(20_000_000)
    entries[0] = ("hidden.0.weight.npy", bomb, zipfile.ZIP_DEFLATED)
    return _zip_entries(entries)


def _corrupt_middle(folder: Path, evil: bytes) -> bytes:
    data = bytearray((FORMAT2 / "residual_ppo" / "policy.npz").read_bytes())
    for i in range(2000, 2100):
        data[i] ^= 0xFF
    return bytes(data)


# ------------------------------------------------------------------ safetensors payloads
def _tensors(folder: Path, name: str) -> dict[str, np.ndarray]:
    return dict(safetensors.numpy.load_file(folder / name))


def _save_tensors(name: str, change: Callable[[dict[str, Any], Path], None]) -> Any:
    """Rewrite a safetensors file of the folder with ``change`` applied to its arrays."""

    def mutate(folder: Path, evil: bytes) -> None:
        arrays = _tensors(folder, name)
        change(arrays, folder)
        safetensors.numpy.save_file(arrays, folder / name)

    return mutate


def _raw_safetensors(header: dict[str, Any] | bytes, data: bytes = b"") -> bytes:
    """A safetensors file written by hand: the header length, the header, the data."""
    text = header if isinstance(header, bytes) else json.dumps(header).encode()
    return len(text).to_bytes(8, "little") + text + data


def _header_of(folder: Path, name: str) -> tuple[dict[str, Any], bytes]:
    raw = (folder / name).read_bytes()
    size = int.from_bytes(raw[:8], "little")
    return json.loads(raw[8 : 8 + size]), raw[8 + size :]


def _edit_header(name: str, edit: Callable[[dict[str, Any]], None], extra: bytes = b"") -> Any:
    def make(folder: Path, evil: bytes) -> bytes:
        header, data = _header_of(folder, name)
        edit(header)
        return _raw_safetensors(header, data + extra)

    return _raw(name, make)


def _duplicate_entry(folder: Path, evil: bytes) -> bytes:
    header, data = _header_of(folder, "policy.safetensors")
    text = json.dumps(header)[:-1] + ', "log_std": ' + json.dumps(header["action.bias"]) + "}"
    return _raw_safetensors(text.encode(), data)


H = "'.*config.json': field "
W = "'.*policy.safetensors'"
N = "'.*obs_norm.safetensors'"
CASES: dict[str, tuple[Callable[[Path, bytes], None], type[Exception], str]] = {
    # ------------------------------------------------------------------------ config.json
    "config :serialized: policy": (
        _edit_config(lambda r: r.__setitem__("policy", _serialized(b""))),
        ValueError,
        H + r"policy\.:type: is not known: allowed fields are type, hidden_sizes",
    ),
    "config :serialized: top level": (
        _config_text(
            lambda t, e: t.rstrip()[:-1] + f', ":serialized:": "{base64.b64encode(e).decode()}"}}'
        ),
        ValueError,
        H + r":serialized: is not known: allowed fields are format, name, env_kwargs",
    ),
    "config :serialized: in train_config": (
        _edit_config(lambda r: r["train_config"].__setitem__("policy_kwargs", _serialized(b""))),
        ValueError,
        H + r"train_config\.policy_kwargs\.:type: is not a valid field name: allowed letters",
    ),
    "config :serialized: at the top of train_config": (
        _edit_config(lambda r: r["train_config"].__setitem__(":serialized:", "gASV")),
        ValueError,
        H + r"train_config\.:serialized: is not a valid field name",
    ),
    "config train_config nested too deeply": (
        _edit_config(_set(("train_config", "net_arch"), [[[[[[1]]]]]])),
        ValueError,
        H + r"train_config\.net_arch\[0\]\[0\]\[0\] is nested too deeply: allowed 4 levels",
    ),
    "config train_config huge integer": (
        _edit_config(_set(("train_config", "seed"), 10**30)),
        ValueError,
        H + r"train_config\.seed = 10{30}: allowed an integer in \[-2\*\*53, 2\*\*53\]",
    ),
    "config train_config 1e400": (
        _config_text(lambda t, e: t.replace('"gamma": 0.995', '"gamma": 1e400')),
        ValueError,
        H + r"train_config\.gamma = inf: allowed a finite number",
    ),
    "config policy_class entry": (
        _edit_config(lambda r: r.__setitem__("policy_class", "stable_baselines3.PPO")),
        ValueError,
        H + r"policy_class is not known: allowed fields are format, name, env_kwargs",
    ),
    "config key with a newline": (
        _edit_config(lambda r: r.__setitem__("evil\nkey\x1b[2J", 1)),
        ValueError,
        H + r"'evil\\nkey\\x1b\[2J' is not known: allowed fields are format",
    ),
    "config unknown env keyword": (
        _edit_config(_set(("env_kwargs", "reward_weights"), {"tracking": 1.0})),
        ValueError,
        H + r"env_kwargs\.reward_weights is not known: allowed fields are base_controller, "
        r"control_dt_s, residual_scale_nm, min_torque_nm, max_torque_nm",
    ),
    "config unregistered base controller": (
        _edit_config(_set(("env_kwargs", "base_controller"), "os.system")),
        ValueError,
        H + r"env_kwargs\.base_controller: the model was trained on base controller "
        r"'os\.system', which is not registered; expected one of \[",
    ),
    "config base controller as a number": (
        _edit_config(_set(("env_kwargs", "base_controller"), 3)),
        ValueError,
        H + r"env_kwargs\.base_controller = 3: allowed a valid string",
    ),
    "config env keyword out of the env's range": (
        _edit_config(_set(("env_kwargs", "control_dt_s"), 0.0)),
        ValueError,
        H + r"env_kwargs\.control_dt_s = 0\.0 is out of range: allowed \[0\.001, 10\]",
    ),
    "config decision period not a multiple of the plant step": (
        _edit_config(_set(("env_kwargs", "control_dt_s"), 0.1234)),
        ValueError,
        H + r"env_kwargs\.control_dt_s = 0\.1234 is out of range: allowed a multiple of plant_dt",
    ),
    "config torque limits inverted": (
        _edit_config(_set(("env_kwargs", "min_torque_nm"), 60000.0)),
        ValueError,
        H + r"env_kwargs\.min_torque_nm = 60000\.0 must be below max_torque_nm = 50000\.0",
    ),
    "config field keyword on the 4-DOF env": (
        _edit_config(_set(("env_kwargs", "observation"), "surface")),
        ValueError,
        H + r"env_kwargs\.observation is a keyword of DrillStringField-v0",
    ),
    "config unknown env id": (
        _edit_config(_set(("env_kwargs", "env_id"), "Evil-v0")),
        ValueError,
        H + r"env_kwargs\.env_id = 'Evil-v0': allowed 'DrillString-v0' or 'DrillStringField-v0'",
    ),
    "config observation size does not match": (
        _edit_config(_set(("observation_size",), 9)),
        ValueError,
        H + r"observation_size: wrong observation size: expected 11 "
        r"\(DrillString-v0 with base_controller='proposed'\), found 9",
    ),
    "config huge observation size": (
        _edit_config(_set(("observation_size",), 10**30)),
        ValueError,
        H + r"observation_size = 1000000000000000000000000000000: allowed less than or equal "
        r"to 1024",
    ),
    "config integer of 400 digits": (
        _edit_config(_set(("observation_size",), 10**400)),
        ValueError,
        H + r"observation_size = an integer of 401 digits: allowed less than or equal to 1024",
    ),
    "config huge hidden size": (
        _edit_config(_set(("policy", "hidden_sizes"), [10**9, 64])),
        ValueError,
        H + r"policy\.hidden_sizes\[0\] = 1000000000: allowed less than or equal to 1024",
    ),
    "config too many hidden layers": (
        _edit_config(_set(("policy", "hidden_sizes"), [8] * 9)),
        ValueError,
        H
        + r"policy\.hidden_sizes = \[8, 8, .*: allowed a valid list|"
        + H
        + r"policy\.hidden_sizes = .*at most 8 items",
    ),
    "config 1e400": (
        _config_text(lambda t, e: t.replace('"control_dt_s": 0.1', '"control_dt_s": 1e400')),
        ValueError,
        H + r"env_kwargs\.control_dt_s = inf: allowed a finite number",
    ),
    "config NaN": (
        _config_text(lambda t, e: t.replace('"control_dt_s": 0.1', '"control_dt_s": NaN')),
        ValueError,
        r"config.json' is not valid JSON: the non-finite number NaN is not allowed",
    ),
    "config Infinity in the record": (
        _config_text(lambda t, e: re.sub(r'"wall_time_s": [0-9.]+', '"wall_time_s": Infinity', t)),
        ValueError,
        r"config.json' is not valid JSON: the non-finite number Infinity is not allowed",
    ),
    "config integer of 5000 digits": (
        _config_text(lambda t, e: re.sub(r'"timesteps": [0-9]+', '"timesteps": ' + "9" * 5000, t)),
        ValueError,
        r"config.json' is not valid JSON: .*(limit|digits)",
    ),
    "config observation size as text": (
        _edit_config(_set(("observation_size",), "11")),
        ValueError,
        H + r"observation_size = '11': allowed a valid integer",
    ),
    "config observation size as float": (
        _edit_config(_set(("observation_size",), 11.0)),
        ValueError,
        H + r"observation_size = 11\.0: allowed a valid integer",
    ),
    "config wrong action bound length": (
        _edit_config(_set(("policy", "action_low"), [-1.0, -1.0])),
        ValueError,
        H + r"policy\.action_low = \[-1\.0, -1\.0\]: allowed a list of 1 \(policy\.action_size\)",
    ),
    "config hidden sizes do not match the weights": (
        _edit_config(_set(("policy", "hidden_sizes"), [32, 32])),
        ValueError,
        W + r": array hidden\.0\.weight has shape \(64, 11\): expected \(32, 11\)",
    ),
    "config two actions": (
        _edit_config(
            lambda r: r["policy"].update(action_size=2, action_low=[-1, -1], action_high=[1, 1])
        ),
        ValueError,
        H + r"policy\.action_size = 2: DrillString-v0 takes one action",
    ),
    "config unknown activation": (
        _edit_config(_set(("policy", "activation"), "__import__('os')")),
        ValueError,
        H + r"policy\.activation = .*: allowed 'tanh' or 'relu'",
    ),
    "config escape codes in the name": (
        _edit_config(_set(("name",), "\x1b[2Jresidual")),
        ValueError,
        H + r"name = '\\x1b\[2Jresidual': allowed printable characters only",
    ),
    "config missing field": (
        _edit_config(lambda r: r.pop("policy")),
        ValueError,
        H + r"policy is missing",
    ),
    "config duplicate key": (
        _config_text(lambda t, e: t.rstrip()[:-1] + ', "name": "other"}'),
        ValueError,
        r"config.json' is not valid JSON: the key 'name' appears twice",
    ),
    "config format 1 without model.zip": (
        _edit_config(_set(("format",), 1)),
        ValueError,
        H + r"format = 1: this is a Stable-Baselines3 model .*trust_pickle=True.*drill-gym convert",
    ),
    "config format 4": (
        _edit_config(_set(("format",), 4)),
        ValueError,
        H + r"format = 4: allowed less than or equal to 3",
    ),
    "config format 2 with safetensors only": (
        _edit_config(_set(("format",), 2)),
        FileNotFoundError,
        r"incomplete model in .*: its config.json is of format 2, which needs policy\.npz, "
        r"obs_norm\.npz; missing policy\.npz, obs_norm\.npz",
    ),
    "config not an object": (
        _raw("config.json", lambda f, e: b"[1, 2, 3]"),
        ValueError,
        r"config.json': expected a JSON object, found list",
    ),
    "config deeply nested": (
        _raw("config.json", lambda f, e: b"[" * 200_000 + b"]" * 200_000),
        ValueError,
        r"config.json' is not valid JSON: nested too deeply",
    ),
    "config is a pickle": (
        _raw("config.json", lambda f, e: e),
        ValueError,
        r"config.json' is not (UTF-8 text|valid JSON)",
    ),
    "config too large": (
        _raw("config.json", lambda f, e: b" " * 2_000_000 + b"{}"),
        ValueError,
        r"config.json': 2000002 bytes is too large: allowed at most 1000000",
    ),
    # ------------------------------------------------- config.json: frame stacking (memory)
    "config frame_stack zero": (
        _edit_config(_set(("policy", "frame_stack"), 0)),
        ValueError,
        H + r"policy\.frame_stack = 0: allowed greater than or equal to 1",
    ),
    "config frame_stack huge": (
        _edit_config(_set(("policy", "frame_stack"), 10**12)),
        ValueError,
        H + r"policy\.frame_stack = 1000000000000: allowed less than or equal to 256",
    ),
    "config frame_stack as text": (
        _edit_config(_set(("policy", "frame_stack"), "4")),
        ValueError,
        H + r"policy\.frame_stack = '4': allowed a valid integer",
    ),
    "config frame_stack as float": (
        _edit_config(_set(("policy", "frame_stack"), 4.0)),
        ValueError,
        H + r"policy\.frame_stack = 4\.0: allowed a valid integer",
    ),
    "config frame_stack as boolean": (
        _edit_config(_set(("policy", "frame_stack"), True)),
        ValueError,
        H + r"policy\.frame_stack = True: allowed a valid integer",
    ),
    "config frame_stack null": (
        _edit_config(_set(("policy", "frame_stack"), None)),
        ValueError,
        H + r"policy\.frame_stack = None: allowed a valid integer",
    ),
    "config frame_stack as code": (
        _edit_config(_set(("policy", "frame_stack"), "__import__('os').system('touch MARKER')")),
        ValueError,
        H + r"policy\.frame_stack = .*: allowed a valid integer",
    ),
    "config frame_stack beyond the input limit": (
        _edit_config(
            lambda r: (
                r.__setitem__("observation_size", 1000),
                r["policy"].__setitem__("frame_stack", 5),
            )
        ),
        ValueError,
        H + r"policy\.frame_stack = 5 is out of range: observation_size 1000 x frame_stack 5 = "
        r"5000 network inputs, allowed at most 4096",
    ),
    "config frame_stack does not match the arrays": (
        _edit_config(_set(("policy", "frame_stack"), 2)),
        ValueError,
        N + r": array mean has shape \(11,\): expected \(22,\)",
    ),
    "config frame_stack outside the policy": (
        _edit_config(_set(("frame_stack",), 4)),
        ValueError,
        H + r"frame_stack is not known: allowed fields are format, name, env_kwargs",
    ),
    "config frame_stack as an env keyword": (
        _edit_config(_set(("env_kwargs", "frame_stack"), 4)),
        ValueError,
        H + r"env_kwargs\.frame_stack is not known: allowed fields are base_controller",
    ),
    "config missing": (
        lambda folder, evil: (folder / "config.json").unlink(),
        FileNotFoundError,
        r"incomplete model in .*missing config\.json",
    ),
    # ------------------------------------------------------------------ policy.safetensors
    "weights pickle renamed": (
        _raw("policy.safetensors", lambda f, e: e),
        ValueError,
        W + r" is not valid policy network weights \(a safetensors file of float arrays\): a "
        r"header of \d+ bytes: allowed 1 to 7680 bytes",
    ),
    "weights .npz renamed": (
        _raw(
            "policy.safetensors",
            lambda f, e: (FORMAT2 / "residual_ppo" / "policy.npz").read_bytes(),
        ),
        ValueError,
        W + r" is not valid policy network weights .*a header of \d+ bytes",
    ),
    "weights empty": (
        _raw("policy.safetensors", lambda f, e: b""),
        ValueError,
        W + r" is not valid policy network weights .*: no header length",
    ),
    "weights header of zero bytes": (
        _raw("policy.safetensors", lambda f, e: bytes(8)),
        ValueError,
        W + r" is not valid policy network weights .*: a header of 0 bytes",
    ),
    "weights header of a gigabyte": (
        _raw("policy.safetensors", lambda f, e: (10**9).to_bytes(8, "little") + b"{}"),
        ValueError,
        W + r" is not valid .*: a header of 1000000000 bytes: allowed 1 to 7680 bytes",
    ),
    "weights header is code": (
        _raw(
            "policy.safetensors",
            lambda f, e: _raw_safetensors(b"__import__('os').system('touch MARKER')"),
        ),
        ValueError,
        W + r" is not valid policy network weights \(a safetensors file of float arrays\): ",
    ),
    "weights header is a pickle": (
        _raw("policy.safetensors", lambda f, e: _raw_safetensors(e)),
        ValueError,
        W + r" is not valid policy network weights \(a safetensors file of float arrays\): ",
    ),
    "weights truncated": (
        _raw(
            "policy.safetensors", lambda f, e: (SHIPPED / "policy.safetensors").read_bytes()[:5000]
        ),
        ValueError,
        W + r" is not valid policy network weights .*",
    ),
    "weights trailing bytes": (
        _raw(
            "policy.safetensors",
            lambda f, e: (SHIPPED / "policy.safetensors").read_bytes() + bytes(30_000_000),
        ),
        ValueError,
        W + r"( is not valid policy network weights|: \d+ bytes is too large)",
    ),
    "weights header declares a huge shape": (
        _edit_header(
            "policy.safetensors",
            lambda h: h["action.bias"].update(shape=[10**12], data_offsets=[0, 4 * 10**12]),
        ),
        ValueError,
        W + r" is not valid policy network weights .*",
    ),
    "weights header declares offsets beyond the file": (
        _edit_header("policy.safetensors", lambda h: h["log_std"].update(data_offsets=[0, 10**15])),
        ValueError,
        W + r" is not valid policy network weights .*",
    ),
    "weights header declares unknown dtype": (
        _edit_header("policy.safetensors", lambda h: h["log_std"].update(dtype="O")),
        ValueError,
        W + r" is not valid policy network weights .*",
    ),
    "weights duplicate entry": (
        _raw("policy.safetensors", _duplicate_entry),
        ValueError,
        W + r" is not valid policy network weights .*",
    ),
    "weights int64": (
        _save_tensors("policy.safetensors", lambda a, f: a.__setitem__("log_std", np.array([1]))),
        ValueError,
        W + r": array log_std has dtype 'I64': allowed F32 or F64 \(float32 or float64\)",
    ),
    "weights float16": (
        _save_tensors(
            "policy.safetensors", lambda a, f: a.__setitem__("log_std", np.ones(1, np.float16))
        ),
        ValueError,
        W + r": array log_std has dtype 'F16': allowed F32 or F64",
    ),
    "weights wrong shape": (
        _save_tensors(
            "policy.safetensors",
            lambda a, f: a.__setitem__("hidden.0.weight", np.zeros((64, 10), np.float32)),
        ),
        ValueError,
        W + r": array hidden\.0\.weight has shape \(64, 10\): expected \(64, 11\)",
    ),
    "weights NaN": (
        _save_tensors(
            "policy.safetensors",
            lambda a, f: a.__setitem__("action.weight", a["action.weight"] * np.nan),
        ),
        ValueError,
        W + r": array action\.weight has non-finite values \(NaN or inf\)",
    ),
    "weights inf": (
        _save_tensors(
            "policy.safetensors",
            lambda a, f: a.__setitem__("hidden.1.bias", a["hidden.1.bias"] + np.inf),
        ),
        ValueError,
        W + r": array hidden\.1\.bias has non-finite values \(NaN or inf\)",
    ),
    "weights extra array": (
        _save_tensors("policy.safetensors", lambda a, f: a.__setitem__("evil", np.zeros(1))),
        ValueError,
        W + r": unexpected array 'evil': expected one each of hidden\.0\.weight",
    ),
    "weights path traversal name": (
        _save_tensors(
            "policy.safetensors", lambda a, f: a.__setitem__("../../log_std", a.pop("log_std"))
        ),
        ValueError,
        W + r": unexpected array '\.\./\.\./log_std'",
    ),
    "weights missing array": (
        _save_tensors("policy.safetensors", lambda a, f: a.pop("log_std")),
        ValueError,
        W + r": missing array\(s\) log_std \(policy network weights\)",
    ),
    "weights is a folder": (
        lambda folder, evil: (
            (folder / "policy.safetensors").unlink(),
            (folder / "policy.safetensors").mkdir(),
        ),
        FileNotFoundError,
        r"incomplete model in .*missing policy\.safetensors",
    ),
    "weights missing": (
        lambda folder, evil: (folder / "policy.safetensors").unlink(),
        FileNotFoundError,
        r"incomplete model in .*missing policy\.safetensors",
    ),
    # ---------------------------------------------------------------- obs_norm.safetensors
    "norm pickle renamed": (
        _raw("obs_norm.safetensors", lambda f, e: e),
        ValueError,
        N + r" is not valid observation normalisation statistics .*a header of \d+ bytes",
    ),
    "norm negative variance": (
        _save_tensors("obs_norm.safetensors", lambda a, f: a.__setitem__("var", -np.ones(11))),
        ValueError,
        N + r": array var has negative entries: allowed >= 0",
    ),
    "norm zero clip": (
        _save_tensors(
            "obs_norm.safetensors", lambda a, f: a.__setitem__("clip_obs", np.array(0.0))
        ),
        ValueError,
        N + r": clip_obs = 0\.0 is out of range: allowed \(0, 1e9\]",
    ),
    "norm clip as a vector": (
        _save_tensors(
            "obs_norm.safetensors", lambda a, f: a.__setitem__("clip_obs", np.array([10.0]))
        ),
        ValueError,
        N + r": array clip_obs has shape \(1,\): expected \(\)",
    ),
    "norm NaN": (
        _save_tensors(
            "obs_norm.safetensors", lambda a, f: a.__setitem__("mean", np.full(11, np.nan))
        ),
        ValueError,
        N + r": array mean has non-finite values",
    ),
    "norm wrong size": (
        _save_tensors("obs_norm.safetensors", lambda a, f: a.__setitem__("mean", np.zeros(9))),
        ValueError,
        N + r": array mean has shape \(9,\): expected \(11,\)",
    ),
    "norm int32": (
        _save_tensors(
            "obs_norm.safetensors", lambda a, f: a.__setitem__("var", np.ones(11, np.int32))
        ),
        ValueError,
        N + r": array var has dtype 'I32': allowed F32 or F64",
    ),
}


@pytest.mark.parametrize("case", list(CASES))
def test_hostile_model_file_is_refused(case: str, tmp_path: Path, marker: Path) -> None:
    mutate, error, message = CASES[case]
    folder = model_copy(tmp_path)
    mutate(folder, payload(marker))
    with pytest.raises(error, match=message) as info:
        load_policy(folder)
    assert "\n" not in str(info.value)
    assert len(str(info.value)) < 600


W2 = "'.*policy.npz'"
N2 = "'.*obs_norm.npz'"
NPZ_CASES: dict[str, tuple[Callable[[Path, bytes], None], type[Exception], str]] = {
    "weights object array": (
        _save_arrays(
            "policy.npz",
            lambda a, e, f: a.__setitem__(
                "action.bias", np.array([_Payload(f.parent / "MARKER")], dtype=object)
            ),
        ),
        ValueError,
        W2 + r": array action\.bias has dtype object: allowed float32 or float64",
    ),
    "weights pickle renamed to .npz": (
        _raw("policy.npz", lambda f, e: e),
        ValueError,
        W2 + r" is not valid policy network weights \(an \.npz archive of float arrays\): "
        r"File is not a zip file",
    ),
    "weights .npy renamed to .npz": (
        _raw("policy.npz", lambda f, e: _npy(np.zeros(3))),
        ValueError,
        W2 + r" is not valid policy network weights .*File is not a zip file",
    ),
    "weights zip bomb": (
        _raw("policy.npz", _zip_bomb),
        ValueError,
        W2 + r": its entries declare \d+ bytes uncompressed: allowed at most \d+ for policy "
        r"network weights \(a zip bomb\?\)",
    ),
    "weights many entries": (
        _raw("policy.npz", lambda f, e: _zip_entries([(f"{i}.npy", b"", 0) for i in range(300)])),
        ValueError,
        W2 + r": 300 entries: expected 7 \(hidden\.0\.weight, ",
    ),
    "weights truncated": (
        _raw(
            "policy.npz", lambda f, e: (FORMAT2 / "residual_ppo" / "policy.npz").read_bytes()[:5000]
        ),
        ValueError,
        W2 + r" is not valid policy network weights .*File is not a zip file",
    ),
    "weights corrupted bytes": (
        _raw("policy.npz", _corrupt_middle),
        ValueError,
        W2 + r" is not valid policy network weights .*(CRC|not a valid \.npy|header)",
    ),
    "weights int64": (
        _save_arrays("policy.npz", lambda a, e, f: a.__setitem__("log_std", np.array([1]))),
        ValueError,
        W2 + r": array log_std has dtype int64: allowed float32 or float64",
    ),
    "weights complex": (
        _save_arrays(
            "policy.npz", lambda a, e, f: a.__setitem__("log_std", np.array([1j], np.complex128))
        ),
        ValueError,
        W2 + r": array log_std has dtype complex128: allowed float32 or float64",
    ),
    "weights wrong shape": (
        _save_arrays(
            "policy.npz", lambda a, e, f: a.__setitem__("hidden.0.weight", np.zeros((64, 10)))
        ),
        ValueError,
        W2 + r": array hidden\.0\.weight has shape \(64, 10\): expected \(64, 11\)",
    ),
    "weights NaN": (
        _save_arrays(
            "policy.npz",
            lambda a, e, f: a.__setitem__("action.weight", a["action.weight"] * np.nan),
        ),
        ValueError,
        W2 + r": array action\.weight has non-finite values \(NaN or inf\)",
    ),
    "weights extra array": (
        _raw(
            "policy.npz",
            lambda f, e: _zip_entries(
                [x for x in _valid_entries(f, "policy.npz") if x[0] != "log_std.npy"]
                + [("evil.npy", _npy(np.array([_Payload(f.parent / "MARKER")])), 0)]
            ),
        ),
        ValueError,
        W2 + r": unexpected entry 'evil\.npy': expected one each of hidden\.0\.weight\.npy",
    ),
    "weights missing array": (
        _save_arrays("policy.npz", lambda a, e, f: a.pop("log_std")),
        ValueError,
        W2 + r": missing array\(s\) log_std \(policy network weights\)",
    ),
    "weights path traversal entry": (
        _replace_entry("policy.npz", "../../log_std.npy", _npy(np.zeros(1)), drop="log_std.npy"),
        ValueError,
        W2 + r": unexpected entry '\.\./\.\./log_std\.npy'",
    ),
    "weights header declares a huge shape": (
        _replace_entry("policy.npz", "action.bias.npy", _npy_header_only((10**12,))),
        ValueError,
        W2 + r": array action\.bias has shape \(1000000000000,\): expected \(1,\)",
    ),
    "weights header declares object dtype": (
        _replace_entry("policy.npz", "action.bias.npy", _npy_header_only((1,), "|O")),
        ValueError,
        W2 + r": array action\.bias has dtype object: allowed float32 or float64",
    ),
    "weights header is code": (
        _replace_entry(
            "policy.npz",
            "action.bias.npy",
            b"\x93NUMPY\x01\x00\x40\x00"
            + b"__import__('os').system('touch MARKER')".ljust(63)
            + b"\n",
        ),
        ValueError,
        W2 + r": entry action\.bias\.npy is not a valid \.npy array",
    ),
    "weights lzma entry": (
        _replace_entry("policy.npz", "action.bias.npy", _npy(np.zeros(1)), zipfile.ZIP_LZMA),
        ValueError,
        W2 + r": entry 'action\.bias\.npy' is encrypted or uses an unsupported compression",
    ),
    "weights missing": (
        lambda folder, evil: (folder / "policy.npz").unlink(),
        FileNotFoundError,
        r"incomplete model in .*of format 2, .*missing policy\.npz",
    ),
    "norm object array": (
        _save_arrays(
            "obs_norm.npz",
            lambda a, e, f: a.__setitem__(
                "mean", np.array([_Payload(f.parent / "MARKER")] * 11, dtype=object)
            ),
        ),
        ValueError,
        N2 + r": array mean has dtype object: allowed float32 or float64",
    ),
    "norm pickle renamed": (
        _raw("obs_norm.npz", lambda f, e: e),
        ValueError,
        N2 + r" is not valid observation normalisation statistics .*File is not a zip file",
    ),
    "norm negative variance": (
        _save_arrays("obs_norm.npz", lambda a, e, f: a.__setitem__("var", -np.ones(11))),
        ValueError,
        N2 + r": array var has negative entries: allowed >= 0",
    ),
    "norm zero clip": (
        _save_arrays("obs_norm.npz", lambda a, e, f: a.__setitem__("clip_obs", np.float64(0))),
        ValueError,
        N2 + r": clip_obs = 0\.0 is out of range: allowed \(0, 1e9\]",
    ),
    "norm NaN": (
        _save_arrays("obs_norm.npz", lambda a, e, f: a.__setitem__("mean", np.full(11, np.nan))),
        ValueError,
        N2 + r": array mean has non-finite values",
    ),
    "norm wrong size": (
        _save_arrays("obs_norm.npz", lambda a, e, f: a.__setitem__("mean", np.zeros(9))),
        ValueError,
        N2 + r": array mean has shape \(9,\): expected \(11,\)",
    ),
    "norm zip bomb": (
        _replace_entry("obs_norm.npz", "mean.npy", _npy_header_only((11,)) + bytes(5_000_000), 8),
        ValueError,
        N2 + r": its entries declare \d+ bytes uncompressed: allowed at most \d+ .*zip bomb",
    ),
}


@pytest.mark.parametrize("case", list(NPZ_CASES))
def test_hostile_previous_format_file_is_refused(case: str, tmp_path: Path, marker: Path) -> None:
    """The same guarantees for a model folder of the previous format (``.npz`` arrays)."""
    mutate, error, message = NPZ_CASES[case]
    folder = model_copy(tmp_path, FORMAT2 / "residual_ppo")
    mutate(folder, payload(marker))
    with pytest.raises(error, match=message) as info:
        load_policy(folder)
    assert "\n" not in str(info.value)
    assert len(str(info.value)) < 600
    with pytest.raises(error, match=message):
        convert_model(folder, tmp_path / "new")
    assert not (tmp_path / "new").exists()


def _legacy_folder(tmp_path: Path, marker: Path, name: str = "model.zip") -> Path:
    """An SB3-style ``.zip`` whose ``policy_class`` is a pickled payload, with a format-1
    config.json and obs_norm.npz beside it (what SB3's PPO.load would unpickle)."""
    folder = tmp_path / "legacy"
    folder.mkdir(exist_ok=True)
    data = {"policy_class": _serialized(payload(marker)), "observation_space": _serialized(b"")}
    with zipfile.ZipFile(folder / name, "w") as archive:
        archive.writestr("data", json.dumps(data))
        archive.writestr("policy.pth", payload(marker))
    record = json.loads((SHIPPED / "config.json").read_text())
    record["format"] = 1
    del record["policy"]
    (folder / "config.json").write_text(json.dumps(record))
    shutil.copy(FORMAT2 / "residual_ppo" / "obs_norm.npz", folder / "obs_norm.npz")
    return folder


def test_sb3_zip_needs_the_opt_in(
    tmp_path: Path, marker: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    folder = _legacy_folder(tmp_path, marker)
    for path in (folder, folder / "model.zip"):
        with pytest.raises(
            ValueError,
            match=r"model\.zip' is a Stable-Baselines3 model \(a pickle\): loading it unpickles "
            r"Python objects, which runs any code the file's author put in it; if you trust its "
            r"source, name that file itself: load_policy\(FILE, trust_pickle=True\) .*"
            r"'drill-gym convert FILE NEW_FOLDER --trust-pickle' \(agents\.convert\.convert_model\)",
        ):
            load_policy(path)
    with pytest.raises(ValueError, match=r"pass trust_pickle=True \(--trust-pickle\) only"):
        convert_model(folder / "model.zip", tmp_path / "new")
    assert cli_main(["convert", str(folder / "model.zip"), str(tmp_path / "new")]) == 2
    err = capsys.readouterr().err
    assert "argument --trust-pickle: is required" in err and err.count("\n") == 1
    assert not (tmp_path / "new").exists()


def test_trust_covers_only_the_named_file(
    tmp_path: Path, marker: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """``--trust-pickle`` with ``dl/trusted.zip`` unpickles that file and never the
    ``model.zip`` beside it; a folder argument never widens the trust."""
    folder = _legacy_folder(tmp_path, marker)  # dl/model.zip: must never run
    allowed = tmp_path / "ALLOWED"
    (tmp_path / "t").mkdir()
    trusted = _legacy_folder(tmp_path / "t", allowed) / "model.zip"  # creates ALLOWED if run
    shutil.copy(trusted, folder / "trusted.zip")
    for argv in (
        [str(folder), str(tmp_path / "new"), "--trust-pickle"],
        [str(folder / "config.json"), str(tmp_path / "new"), "--trust-pickle"],
    ):
        assert cli_main(["convert", *argv]) == 2
        err = capsys.readouterr().err
        assert "--trust-pickle covers only the file you name" in err and err.count("\n") == 1
    with pytest.raises(ValueError, match=r"model\.zip' is a Stable-Baselines3 model"):
        load_policy(folder, trust_pickle=True)
    assert not allowed.exists() and not (tmp_path / "new").exists()
    pytest.importorskip("stable_baselines3")
    # The named file is opened (its payload runs: the trust was granted for it) and fails
    # as an SB3 model; model.zip beside it is never opened (the marker fixture checks).
    code = cli_main(
        ["convert", str(folder / "trusted.zip"), str(tmp_path / "new"), "--trust-pickle"]
    )
    err = capsys.readouterr().err
    assert code == 2 and "trusted.zip' is not a valid Stable-Baselines3 PPO model" in err, err
    assert allowed.exists()
    assert not (tmp_path / "new").exists()


def test_convert_refuses_a_destination_holding_other_files(tmp_path: Path) -> None:
    notes = tmp_path / "notes"
    notes.mkdir()
    (notes / "config.json").write_text("my notes")
    with pytest.raises(ValueError, match=r"destination '.*notes' holds other files"):
        convert_model(FORMAT2 / "residual_ppo", notes)
    assert (notes / "config.json").read_text() == "my notes"
    (tmp_path / "file").write_text("mine")
    with pytest.raises(ValueError, match=r"destination '.*file' exists and is not a folder"):
        convert_model(FORMAT2 / "residual_ppo", tmp_path / "file")
    assert (tmp_path / "file").read_text() == "mine"


def test_evaluate_refuses_an_sb3_zip_in_one_line(
    tmp_path: Path, marker: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    folder = _legacy_folder(tmp_path, marker)
    assert cli_main(["evaluate", str(folder), "--out", str(tmp_path / "out")]) == 2
    err = capsys.readouterr().err
    assert err.startswith("drill-gym evaluate: error: ") and err.count("\n") == 1
    assert "--trust-pickle" in err and "drill-gym convert" in err


def test_portable_files_win_over_a_model_zip_beside_them(tmp_path: Path, marker: Path) -> None:
    for source in (SHIPPED, FORMAT2 / "residual_ppo"):
        folder = model_copy(tmp_path / source.parent.name, source)
        (folder / "model.zip").write_bytes(payload(marker))
        policy = load_policy(folder)  # the zip is never opened
        assert policy.name == "residual_ppo"


# ----------------------------------------------------------------------- every field, fuzzed
HOSTILE_VALUES: tuple[Any, ...] = (
    None, True, 0, -1, 10**400, 1e300, float("inf"), "", "x" * 20_000, "\x1b[2J",
    [], [None], {}, {":serialized:": "gASV"}, [[[[[[[[1]]]]]]]],
)  # fmt: skip


def _leaves(value: Any, path: tuple[Any, ...] = ()) -> Iterator[tuple[Any, ...]]:
    """The path of every entry of a parsed config, containers included."""
    if path:
        yield path
    items = (
        value.items()
        if isinstance(value, dict)
        else enumerate(value)
        if isinstance(value, list)
        else ()
    )
    for key, item in items:
        yield from _leaves(item, (*path, key))


@pytest.mark.parametrize("source", SHIPPED_NAMES)
def test_every_config_entry_replaced_by_hostile_values_is_one_line(source: str) -> None:
    """Each entry of each shipped config.json, replaced by each hostile value: the config is
    accepted or refused with a one-line ValueError naming the file; nothing else escapes."""
    from agents.model_format import validate_config

    original = json.loads((DEFAULT_MODEL_DIR / source / "config.json").read_text())
    refused = 0
    for path in _leaves(original):
        for value in HOSTILE_VALUES:
            record = json.loads(json.dumps(original))
            _set(path, value)(record)
            try:
                validate_config(record, "cfg.json")
            except ValueError as err:
                refused += 1
                assert str(err).startswith("'cfg.json'") and "\n" not in str(err), err
                assert len(str(err)) < 600, err
    assert refused > 500


def test_random_bytes_in_the_weights_are_refused_or_read_finite(tmp_path: Path) -> None:
    """Flipped bytes anywhere in policy.safetensors (the header included): a one-line
    ValueError naming the file, or finite arrays of the expected shapes; nothing else."""
    from agents.model_format import read_safetensors

    spec = load_policy(SHIPPED).spec
    original = (SHIPPED / "policy.safetensors").read_bytes()
    header = int.from_bytes(original[:8], "little")
    rng = np.random.default_rng(7)
    path = tmp_path / "policy.safetensors"
    outcomes = {"refused": 0, "read": 0}
    for trial in range(300):
        data = bytearray(original)
        end = 8 + header if trial % 2 else len(data)  # half of the trials hit the header
        for i in rng.integers(0, end, size=int(rng.integers(1, 4))):
            data[i] = int(rng.integers(0, 256))
        path.write_bytes(bytes(data))
        try:
            arrays = read_safetensors(path, spec.weight_shapes(), "policy network weights")
        except ValueError as err:
            outcomes["refused"] += 1
            assert str(err).startswith(repr(str(path))) and "\n" not in str(err), err
        else:
            outcomes["read"] += 1
            assert all(np.all(np.isfinite(a)) for a in arrays.values())
            assert {k: a.shape for k, a in arrays.items()} == spec.weight_shapes()
    assert outcomes["refused"] > 50 and outcomes["read"] > 50, outcomes


# ------------------------------------------------------------------------- the shipped agent
def _recorded_observations(name: str = "residual_ppo", seeds: tuple[int, ...] = (1, 2)) -> Any:
    policy = load_policy(DEFAULT_MODEL_DIR / name)
    obs = []
    for seed in seeds:
        env = gym.make(
            policy.env_id, max_episode_steps=-1, randomize=True, episode_s=20.0,
            **policy.env_kwargs,
        )  # fmt: skip
        obs.append(np.asarray(rollout(env, policy, seed).observations, dtype=np.float32))
    return np.concatenate(obs)


@pytest.mark.parametrize("name", CONVERTED_NAMES)
def test_shipped_models_are_the_previous_format_converted_bit_for_bit(
    name: str, tmp_path: Path
) -> None:
    """Each shipped model acts as its format-2 original (read by the previous format's
    reader) to the last bit, its arrays are the original's bytes, and ``drill-gym convert``
    of the original writes exactly the shipped files."""
    old = load_policy(FORMAT2 / name)
    new = load_policy(DEFAULT_MODEL_DIR / name)
    assert old.metadata["format"] == 2 and new.metadata["format"] == 3
    obs = _recorded_observations(name, seeds=(1,))
    assert len(obs) >= 100
    new_actions, _ = new.predict(obs)
    old_actions, _ = old.predict(obs)
    assert np.ptp(new_actions) > 0.05  # the agent acts, not a constant
    np.testing.assert_array_equal(new_actions, old_actions)
    assert new_actions.tobytes() == old_actions.tobytes()
    for old_file, new_file in (
        ("policy.npz", "policy.safetensors"),
        ("obs_norm.npz", "obs_norm.safetensors"),
    ):
        with np.load(FORMAT2 / name / old_file) as before:
            after = _tensors(DEFAULT_MODEL_DIR / name, new_file)
            assert sorted(before.files) == sorted(after)
            for key in before.files:
                assert (
                    before[key].dtype == after[key].dtype and before[key].shape == after[key].shape
                )
                assert before[key].tobytes() == after[key].tobytes(), key
    out = tmp_path / name
    convert_model(FORMAT2 / name, out)
    for file in ("config.json", "policy.safetensors", "obs_norm.safetensors"):
        assert (out / file).read_bytes() == (DEFAULT_MODEL_DIR / name / file).read_bytes(), file
    shipped = json.loads((DEFAULT_MODEL_DIR / name / "config.json").read_text())
    original = json.loads((FORMAT2 / name / "config.json").read_text())
    assert shipped == {**original, "format": 3}


def test_shipped_agent_matches_torch_and_sb3_forward_passes() -> None:
    """The NumPy policy against (a) a torch network and (b) an SB3 PPO model, both built here
    from the shipped arrays (read with safetensors' own reader), on recorded observations."""
    th = pytest.importorskip("torch")
    ppo = pytest.importorskip("stable_baselines3")
    obs = _recorded_observations()
    policy = load_policy(SHIPPED)
    weights = {k: th.as_tensor(v) for k, v in _tensors(SHIPPED, "policy.safetensors").items()}
    n = _tensors(SHIPPED, "obs_norm.safetensors")
    mean, var = th.as_tensor(n["mean"]), th.as_tensor(n["var"])
    clip, eps = float(n["clip_obs"]), float(n["epsilon"])
    z = th.clamp((th.as_tensor(obs, dtype=th.float64) - mean) / th.sqrt(var + eps), -clip, clip)
    z = z.float()
    net = th.nn.Sequential(
        th.nn.Linear(11, 64), th.nn.Tanh(), th.nn.Linear(64, 64), th.nn.Tanh(), th.nn.Linear(64, 1)
    )
    with th.no_grad():
        for index, key in ((0, "hidden.0"), (2, "hidden.1"), (4, "action")):
            net[index].weight.copy_(weights[f"{key}.weight"])
            net[index].bias.copy_(weights[f"{key}.bias"])
        torch_actions = th.clamp(net(z), -1.0, 1.0).numpy()
    env = gym.make("DrillString-v0", **policy.env_kwargs)
    model = ppo.PPO(
        "MlpPolicy",
        env,
        policy_kwargs={"net_arch": [64, 64], "activation_fn": th.nn.Tanh},
        device="cpu",
    )
    actor = model.policy
    with th.no_grad():
        for index, key in ((0, "hidden.0"), (2, "hidden.1")):
            actor.mlp_extractor.policy_net[index].weight.copy_(weights[f"{key}.weight"])
            actor.mlp_extractor.policy_net[index].bias.copy_(weights[f"{key}.bias"])
        actor.action_net.weight.copy_(weights["action.weight"])
        actor.action_net.bias.copy_(weights["action.bias"])
    sb3_actions, _ = model.predict(z.numpy(), deterministic=True)
    actions, _ = policy.predict(obs)
    assert np.ptp(actions) > 0.1  # the agent acts, not a constant
    np.testing.assert_allclose(actions, torch_actions, atol=1e-5)
    np.testing.assert_allclose(actions, sb3_actions, atol=1e-5)


_BLOCK = """
import json, sys
class _Block:
    def find_spec(self, name, path=None, target=None):
        if name.split(".")[0] in ("torch", "stable_baselines3"):
            raise ImportError(f"{name} is blocked in this test")
        return None
sys.meta_path.insert(0, _Block())
sys.modules["torch"] = None
sys.modules["stable_baselines3"] = None
"""


def test_shipped_agent_loads_and_predicts_without_torch(tmp_path: Path) -> None:
    obs = _recorded_observations()[::25]
    code = _BLOCK + (
        "import numpy as np, agents\n"
        "policy = agents.load_default_policy()\n"
        f"actions, _ = policy.predict(np.array({obs.tolist()!r}, dtype=np.float32))\n"
        "assert 'torch' not in [m for m in sys.modules if sys.modules[m] is not None]\n"
        "print(json.dumps(actions.ravel().tolist()))\n"
    )
    result = subprocess.run(
        [sys.executable, "-c", code], cwd=ROOT, capture_output=True, text=True, check=False
    )
    assert result.returncode == 0, result.stderr
    expected, _ = load_policy(SHIPPED).predict(obs)
    np.testing.assert_array_equal(np.array(json.loads(result.stdout)), expected.ravel())


def test_evaluate_runs_without_torch(tmp_path: Path) -> None:
    out = tmp_path / "eval"
    argv = ["evaluate", "--scenarios", "h14", "--controllers", "proposed", "--no-figures"]
    code = _BLOCK + (
        f"from experiments.cli import main\nraise SystemExit(main({[*argv, '--out', str(out)]!r}))\n"
    )
    result = subprocess.run(
        [sys.executable, "-c", code], cwd=ROOT, capture_output=True, text=True, check=False
    )
    assert result.returncode == 0, result.stderr
    rows = json.loads((out / "heldout.json").read_text())
    assert {r["controller"] for r in rows} == {"proposed", "residual_ppo", "direct_ppo"}


# ----------------------------------------------------------------------- resume checkpoints
@pytest.fixture(scope="module")
def finished_run(tmp_path_factory: pytest.TempPathFactory) -> Any:
    """A tiny run with its checkpoints (needs torch and SB3)."""
    pytest.importorskip("stable_baselines3")
    from agents.config import TrainConfig
    from agents.train import train

    root = tmp_path_factory.mktemp("run")
    config = TrainConfig(
        run_dir=str(root / "run"), total_timesteps=128, num_envs=2, n_steps=64,
        batch_size=64, n_epochs=1, episode_s=10.0, checkpoint_every=0, validate_every=0,
        tensorboard=False,
    )  # fmt: skip
    train(config)
    return config


def _resume(config: Any, run_dir: Path, **changes: Any) -> None:
    """Resume the run in ``run_dir`` to 256 decisions with the settings ``changes``, recorded
    in its ``config.json`` first (a resumed run keeps its recorded settings)."""
    from agents.train import train

    if changes:
        record = json.loads((run_dir / "config.json").read_text())
        (run_dir / "config.json").write_text(json.dumps({**record, **changes}))
    train(
        dataclasses.replace(
            config, run_dir=str(run_dir), resume=True, total_timesteps=256, **changes
        )
    )


def _checkpoint_cases() -> dict[str, tuple[Callable[[Path, bytes], None], str]]:
    def write(name: str, data: Callable[[Path, bytes], bytes]) -> Callable[[Path, bytes], None]:
        return lambda ck, evil: (ck / name).write_bytes(data(ck, evil))

    def int_arrays(ck: Path, evil: bytes) -> bytes:
        arrays = dict(safetensors.numpy.load_file(ck / "vecnormalize.safetensors"))
        arrays["obs_mean"] = np.arange(11)
        return safetensors.numpy.save(arrays)

    def training(change: Callable[[dict[str, Any], bytes], None]) -> Callable[[Path, bytes], None]:
        def mutate(ck: Path, evil: bytes) -> None:
            record = json.loads((ck / "training.json").read_text())
            change(record, evil)
            (ck / "training.json").write_text(json.dumps(record))

        return mutate

    def padded(ck: Path, evil: bytes) -> bytes:
        return (ck / "training_state.safetensors").read_bytes() + bytes(30_000_000)

    return {
        "training_state is a pickle": (
            write("training_state.safetensors", lambda ck, e: e),
            r"training_state.safetensors' is not valid training state .*a header of \d+ bytes",
        ),
        "training_state padded with 30 MB": (
            write("training_state.safetensors", padded),
            r"training_state.safetensors' is not valid training state .*not fully covered",
        ),
        "training_state header of a gigabyte": (
            write("training_state.safetensors", lambda ck, e: (10**9).to_bytes(8, "little")),
            r"training_state.safetensors' is not valid .*a header of 1000000000 bytes",
        ),
        "vecnormalize integer arrays": (
            write("vecnormalize.safetensors", int_arrays),
            r"vecnormalize.safetensors': array obs_mean has dtype 'I64': allowed F32 or F64",
        ),
        "vecnormalize is a pickle": (
            write("vecnormalize.safetensors", lambda ck, e: e),
            r"vecnormalize.safetensors' is not valid VecNormalize statistics .*a header of",
        ),
        "training.json :serialized:": (
            training(lambda r, e: r.__setitem__(":serialized:", base64.b64encode(e).decode())),
            r"training.json': field :serialized: is not known: allowed fields are format, "
            r"num_timesteps, n_updates, optimizer_state",
        ),
        "training.json huge number": (
            training(lambda r, e: r.__setitem__("num_timesteps", 10**40)),
            rf"training.json': field num_timesteps = {10**40}: allowed less than or equal to "
            r"9007199254740992",
        ),
        "training.json NaN": (
            lambda ck, evil: (ck / "training.json").write_text(
                '{"format": 3, "num_timesteps": NaN}'
            ),
            r"training.json' is not valid JSON: the non-finite number NaN is not allowed",
        ),
        "training.json of format 2 without its .npz files": (
            training(lambda r, e: r.__setitem__("format", 2)),
            r"training_state.npz': no such file",
        ),
    }


@pytest.mark.parametrize("case", list(_checkpoint_cases()))
def test_hostile_checkpoint_is_refused(
    case: str, finished_run: Any, tmp_path: Path, marker: Path
) -> None:
    mutate, message = _checkpoint_cases()[case]
    run_dir = tmp_path / "run"
    shutil.copytree(finished_run.resolved_run_dir(), run_dir)
    mutate(run_dir / "checkpoints" / "steps_128", payload(marker))
    with pytest.raises((ValueError, FileNotFoundError), match=message) as info:
        _resume(finished_run, run_dir)
    assert "\n" not in str(info.value)


def test_checkpoint_of_other_settings_names_the_array(finished_run: Any, tmp_path: Path) -> None:
    run_dir = tmp_path / "run"
    shutil.copytree(finished_run.resolved_run_dir(), run_dir)
    with pytest.raises(
        ValueError,
        match=r"training_state.safetensors': array policy/mlp_extractor.policy_net.0.weight has "
        r"shape "
        r"\(64, 11\): expected \(32, 11\)",
    ):
        _resume(finished_run, run_dir, net_arch=[32, 32])


def test_checkpoint_of_the_previous_format_resumes(finished_run: Any, tmp_path: Path) -> None:
    """A checkpoint written by the previous version (``.npz`` arrays, training.json of format
    2) resumes as the safetensors one does."""
    run_dir = tmp_path / "run"
    shutil.copytree(finished_run.resolved_run_dir(), run_dir)
    ck = run_dir / "checkpoints" / "steps_128"
    for name in ("training_state", "vecnormalize"):
        arrays = _tensors(ck, f"{name}.safetensors")
        np.savez(ck / f"{name}.npz", **arrays)  # type: ignore[arg-type]
        (ck / f"{name}.safetensors").unlink()
    record = json.loads((ck / "training.json").read_text())
    (ck / "training.json").write_text(json.dumps({**record, "format": 2}))
    _resume(finished_run, run_dir)
    assert (run_dir / "checkpoints" / "steps_256" / "training_state.safetensors").is_file()


def test_pickled_checkpoint_needs_trust_pickle(
    finished_run: Any, tmp_path: Path, marker: Path
) -> None:
    run_dir = tmp_path / "run"
    shutil.copytree(finished_run.resolved_run_dir(), run_dir)
    folder = run_dir / "checkpoints"
    legacy = _legacy_folder(tmp_path, marker) / "model.zip"
    shutil.copy(legacy, folder / "rl_model_1024_steps.zip")
    (folder / "rl_model_vecnormalize_1024_steps.pkl").write_bytes(payload(marker))
    with pytest.raises(
        ValueError,
        match=r"--resume: the last checkpoint .*rl_model_1024_steps.zip' is a pickled "
        r"Stable-Baselines3 checkpoint of an older version: loading it unpickles .*pass "
        r"--trust-pickle only if you wrote it yourself",
    ):
        _resume(finished_run, run_dir)


def test_hostile_best_score_is_refused(finished_run: Any, tmp_path: Path, marker: Path) -> None:
    run_dir = tmp_path / "run"
    shutil.copytree(finished_run.resolved_run_dir(), run_dir)
    (run_dir / "best").mkdir()
    (run_dir / "best" / "score.json").write_text(json.dumps({"score": _serialized(b"x")}))
    with pytest.raises(ValueError, match=r"score.json': field score = .* expected a number"):
        _resume(finished_run, run_dir, validate_every=64, validation_episodes=1)
    for steps in (64.5, "64", -1, True):
        (run_dir / "best" / "score.json").write_text(json.dumps({"score": 1, "timesteps": steps}))
        with pytest.raises(ValueError, match=r"score.json': field timesteps = .* expected an int"):
            _resume(finished_run, run_dir, validate_every=64, validation_episodes=1)
