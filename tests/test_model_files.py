"""Model and checkpoint files from others: hostile payloads in every slot a loader reads.

Each payload would create a marker file if it were ever unpickled or executed; every load
must fail with a one-line ``ValueError``/``FileNotFoundError`` naming the file and what is
wrong, and the marker must never appear. Also: the shipped agent against a torch forward
pass and an SB3 model of its weights, built here, and loading and evaluating it in a Python
where torch and Stable-Baselines3 cannot be imported.
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

import drill_env  # noqa: F401
from agents import DEFAULT_MODEL_DIR, load_policy
from agents.convert import convert_sb3_model
from agents.convert import main as convert_main
from drill_env.evaluation import rollout
from experiments.cli import main as cli_main

SHIPPED = DEFAULT_MODEL_DIR / "residual_ppo"
ROOT = Path(__file__).resolve().parents[1]


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


def model_copy(tmp_path: Path) -> Path:
    folder = tmp_path / "model"
    shutil.copytree(SHIPPED, folder)
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
    data = bytearray((SHIPPED / "policy.npz").read_bytes())
    for i in range(2000, 2100):
        data[i] ^= 0xFF
    return bytes(data)


H = "'.*config.json': field "
W = "'.*policy.npz'"
N = "'.*obs_norm.npz'"
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
        H + r":serialized: is not a valid field name",
    ),
    "config :serialized: in train_config": (
        _edit_config(lambda r: r["train_config"].__setitem__("policy_kwargs", _serialized(b""))),
        ValueError,
        H + r"train_config\.policy_kwargs\.:type: is not a valid field name",
    ),
    "config policy_class entry": (
        _edit_config(lambda r: r.__setitem__("policy_class", "stable_baselines3.PPO")),
        ValueError,
        H + r"policy_class is not known: allowed fields are format, name, env_kwargs",
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
    "config observation size does not match": (
        _edit_config(_set(("observation_size",), 9)),
        ValueError,
        H + r"observation_size: wrong observation size: expected 11 "
        r"\(DrillString-v0 with base_controller='proposed'\), found 9",
    ),
    "config huge observation size": (
        _edit_config(_set(("observation_size",), 10**30)),
        ValueError,
        H + r"observation_size = 1000000000000000000000000000000 is out of range: "
        r"allowed an integer in \[1, 1024\]",
    ),
    "config huge hidden size": (
        _edit_config(_set(("policy", "hidden_sizes"), [10**9, 64])),
        ValueError,
        H + r"policy\.hidden_sizes\[0\] = 1000000000 is out of range: allowed an integer in "
        r"\[1, 1024\]",
    ),
    "config 1e400": (
        _config_text(lambda t, e: t.replace('"control_dt_s": 0.1', '"control_dt_s": 1e400')),
        ValueError,
        H + r"env_kwargs\.control_dt_s = inf is out of range: allowed a finite number",
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
        H + r"observation_size = '11' is out of range: allowed an integer",
    ),
    "config observation size as float": (
        _edit_config(_set(("observation_size",), 11.0)),
        ValueError,
        H + r"observation_size = 11\.0 is out of range: allowed an integer",
    ),
    "config wrong action bound length": (
        _edit_config(_set(("policy", "action_low"), [-1.0, -1.0])),
        ValueError,
        H + r"policy\.action_low = \[-1\.0, -1\.0\] is not valid: allowed a list of 1",
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
        H + r"policy\.activation = .* is not valid: allowed \['tanh', 'relu'\]",
    ),
    "config escape codes in the name": (
        _edit_config(_set(("name",), "\x1b[2Jresidual")),
        ValueError,
        H + r"name = .* is not valid: allowed a printable string",
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
        H + r"format = 1: this is a Stable-Baselines3 model .*trust_pickle=True.*agents\.convert",
    ),
    "config format 3": (
        _edit_config(_set(("format",), 3)),
        ValueError,
        H + r"format = 3 is not valid: allowed \[2\]",
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
        H + r"policy\.frame_stack = 0 is out of range: allowed an integer in \[1, 256\]",
    ),
    "config frame_stack huge": (
        _edit_config(_set(("policy", "frame_stack"), 10**12)),
        ValueError,
        H + r"policy\.frame_stack = 1000000000000 is out of range: allowed an integer in "
        r"\[1, 256\]",
    ),
    "config frame_stack as text": (
        _edit_config(_set(("policy", "frame_stack"), "4")),
        ValueError,
        H + r"policy\.frame_stack = '4' is out of range: allowed an integer",
    ),
    "config frame_stack as float": (
        _edit_config(_set(("policy", "frame_stack"), 4.0)),
        ValueError,
        H + r"policy\.frame_stack = 4\.0 is out of range: allowed an integer",
    ),
    "config frame_stack as boolean": (
        _edit_config(_set(("policy", "frame_stack"), True)),
        ValueError,
        H + r"policy\.frame_stack = True is out of range: allowed an integer",
    ),
    "config frame_stack null": (
        _edit_config(_set(("policy", "frame_stack"), None)),
        ValueError,
        H + r"policy\.frame_stack = None is out of range: allowed an integer",
    ),
    "config frame_stack as code": (
        _edit_config(_set(("policy", "frame_stack"), "__import__('os').system('touch MARKER')")),
        ValueError,
        H + r"policy\.frame_stack = .* is out of range: allowed an integer",
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
    # ------------------------------------------------------------------------- policy.npz
    "weights object array": (
        _save_arrays(
            "policy.npz",
            lambda a, e, f: a.__setitem__(
                "action.bias", np.array([_Payload(f.parent / "MARKER")], dtype=object)
            ),
        ),
        ValueError,
        W + r": array action\.bias has dtype object: allowed float32 or float64",
    ),
    "weights pickle renamed to .npz": (
        _raw("policy.npz", lambda f, e: e),
        ValueError,
        W + r" is not valid policy network weights \(an \.npz archive of float arrays\): "
        r"File is not a zip file",
    ),
    "weights .npy renamed to .npz": (
        _raw("policy.npz", lambda f, e: _npy(np.zeros(3))),
        ValueError,
        W + r" is not valid policy network weights .*File is not a zip file",
    ),
    "weights zip bomb": (
        _raw("policy.npz", _zip_bomb),
        ValueError,
        W + r": its entries declare \d+ bytes uncompressed: allowed at most \d+ for policy "
        r"network weights \(a zip bomb\?\)",
    ),
    "weights many entries": (
        _raw("policy.npz", lambda f, e: _zip_entries([(f"{i}.npy", b"", 0) for i in range(300)])),
        ValueError,
        W + r": 300 entries: expected 7 \(hidden\.0\.weight, ",
    ),
    "weights truncated": (
        _raw("policy.npz", lambda f, e: (SHIPPED / "policy.npz").read_bytes()[:5000]),
        ValueError,
        W + r" is not valid policy network weights .*File is not a zip file",
    ),
    "weights corrupted bytes": (
        _raw("policy.npz", _corrupt_middle),
        ValueError,
        W + r" is not valid policy network weights .*(CRC|not a valid \.npy|header)",
    ),
    "weights int64": (
        _save_arrays("policy.npz", lambda a, e, f: a.__setitem__("log_std", np.array([1]))),
        ValueError,
        W + r": array log_std has dtype int64: allowed float32 or float64",
    ),
    "weights complex": (
        _save_arrays(
            "policy.npz", lambda a, e, f: a.__setitem__("log_std", np.array([1j], np.complex128))
        ),
        ValueError,
        W + r": array log_std has dtype complex128: allowed float32 or float64",
    ),
    "weights wrong shape": (
        _save_arrays(
            "policy.npz", lambda a, e, f: a.__setitem__("hidden.0.weight", np.zeros((64, 10)))
        ),
        ValueError,
        W + r": array hidden\.0\.weight has shape \(64, 10\): expected \(64, 11\)",
    ),
    "weights NaN": (
        _save_arrays(
            "policy.npz",
            lambda a, e, f: a.__setitem__("action.weight", a["action.weight"] * np.nan),
        ),
        ValueError,
        W + r": array action\.weight has non-finite values \(NaN or inf\)",
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
        W + r": unexpected entry 'evil\.npy': expected one each of hidden\.0\.weight\.npy",
    ),
    "weights missing array": (
        _save_arrays("policy.npz", lambda a, e, f: a.pop("log_std")),
        ValueError,
        W + r": missing array\(s\) log_std \(policy network weights\)",
    ),
    "weights path traversal entry": (
        _replace_entry("policy.npz", "../../log_std.npy", _npy(np.zeros(1)), drop="log_std.npy"),
        ValueError,
        W + r": unexpected entry '\.\./\.\./log_std\.npy'",
    ),
    "weights header declares a huge shape": (
        _replace_entry("policy.npz", "action.bias.npy", _npy_header_only((10**12,))),
        ValueError,
        W + r": array action\.bias has shape \(1000000000000,\): expected \(1,\)",
    ),
    "weights header declares object dtype": (
        _replace_entry("policy.npz", "action.bias.npy", _npy_header_only((1,), "|O")),
        ValueError,
        W + r": array action\.bias has dtype object: allowed float32 or float64",
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
        W + r": entry action\.bias\.npy is not a valid \.npy array",
    ),
    "weights lzma entry": (
        _replace_entry("policy.npz", "action.bias.npy", _npy(np.zeros(1)), zipfile.ZIP_LZMA),
        ValueError,
        W + r": entry 'action\.bias\.npy' is encrypted or uses an unsupported compression",
    ),
    "weights missing": (
        lambda folder, evil: (folder / "policy.npz").unlink(),
        FileNotFoundError,
        r"incomplete model in .*missing policy\.npz",
    ),
    # ----------------------------------------------------------------------- obs_norm.npz
    "norm object array": (
        _save_arrays(
            "obs_norm.npz",
            lambda a, e, f: a.__setitem__(
                "mean", np.array([_Payload(f.parent / "MARKER")] * 11, dtype=object)
            ),
        ),
        ValueError,
        N + r": array mean has dtype object: allowed float32 or float64",
    ),
    "norm pickle renamed": (
        _raw("obs_norm.npz", lambda f, e: e),
        ValueError,
        N + r" is not valid observation normalisation statistics .*File is not a zip file",
    ),
    "norm negative variance": (
        _save_arrays("obs_norm.npz", lambda a, e, f: a.__setitem__("var", -np.ones(11))),
        ValueError,
        N + r": array var has negative entries: allowed >= 0",
    ),
    "norm zero clip": (
        _save_arrays("obs_norm.npz", lambda a, e, f: a.__setitem__("clip_obs", np.float64(0))),
        ValueError,
        N + r": clip_obs = 0\.0 is out of range: allowed \(0, 1e9\]",
    ),
    "norm NaN": (
        _save_arrays("obs_norm.npz", lambda a, e, f: a.__setitem__("mean", np.full(11, np.nan))),
        ValueError,
        N + r": array mean has non-finite values",
    ),
    "norm wrong size": (
        _save_arrays("obs_norm.npz", lambda a, e, f: a.__setitem__("mean", np.zeros(9))),
        ValueError,
        N + r": array mean has shape \(9,\): expected \(11,\)",
    ),
    "norm zip bomb": (
        _replace_entry("obs_norm.npz", "mean.npy", _npy_header_only((11,)) + bytes(5_000_000), 8),
        ValueError,
        N + r": its entries declare \d+ bytes uncompressed: allowed at most \d+ .*zip bomb",
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


def _legacy_folder(tmp_path: Path, marker: Path) -> Path:
    """An SB3-style model.zip whose ``policy_class`` is a pickled payload, with a format-1
    config.json and obs_norm.npz beside it (what SB3's PPO.load would unpickle)."""
    folder = tmp_path / "legacy"
    folder.mkdir()
    data = {"policy_class": _serialized(payload(marker)), "observation_space": _serialized(b"")}
    with zipfile.ZipFile(folder / "model.zip", "w") as archive:
        archive.writestr("data", json.dumps(data))
        archive.writestr("policy.pth", payload(marker))
    record = json.loads((SHIPPED / "config.json").read_text())
    record["format"] = 1
    del record["policy"]
    (folder / "config.json").write_text(json.dumps(record))
    shutil.copy(SHIPPED / "obs_norm.npz", folder / "obs_norm.npz")
    return folder


def test_sb3_zip_needs_the_opt_in(tmp_path: Path, marker: Path) -> None:
    folder = _legacy_folder(tmp_path, marker)
    for path in (folder, folder / "model.zip"):
        with pytest.raises(
            ValueError,
            match=r"model\.zip' is a Stable-Baselines3 model \(a pickle\): loading it unpickles "
            r"Python objects, which runs any code the file's author put in it; if you trust its "
            r"source, load it with trust_pickle=True .*python -m agents\.convert OLD_FOLDER "
            r"NEW_FOLDER --trust-pickle' \(agents\.convert\.convert_sb3_model\)",
        ):
            load_policy(path)
    with pytest.raises(ValueError, match=r"pass trust_pickle=True \(--trust-pickle\) only"):
        convert_sb3_model(folder, tmp_path / "new")
    with pytest.raises(SystemExit):
        convert_main([str(folder), str(tmp_path / "new")])
    assert not (tmp_path / "new").exists()


def test_evaluate_refuses_an_sb3_zip_in_one_line(
    tmp_path: Path, marker: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    folder = _legacy_folder(tmp_path, marker)
    assert cli_main(["evaluate", str(folder), "--out", str(tmp_path / "out")]) == 2
    err = capsys.readouterr().err
    assert err.startswith("drill-gym evaluate: error: ") and err.count("\n") == 1
    assert "--trust-pickle" in err and "agents.convert" in err


def test_portable_files_win_over_a_model_zip_beside_them(tmp_path: Path, marker: Path) -> None:
    folder = model_copy(tmp_path)
    (folder / "model.zip").write_bytes(payload(marker))
    policy = load_policy(folder)  # the zip is never opened
    assert policy.name == "residual_ppo"


# ------------------------------------------------------------------------- the shipped agent
def _recorded_observations() -> np.ndarray:
    policy = load_policy(SHIPPED)
    obs = []
    for seed in (1, 2):
        env = gym.make(
            "DrillString-v0", max_episode_steps=-1, randomize=True, episode_s=20.0,
            **policy.env_kwargs,
        )  # fmt: skip
        obs.append(np.asarray(rollout(env, policy, seed).observations, dtype=np.float32))
    return np.concatenate(obs)


def test_shipped_agent_matches_torch_and_sb3_forward_passes() -> None:
    """The NumPy policy against (a) a torch network and (b) an SB3 PPO model, both built here
    from the shipped arrays (read with plain np.load), on recorded observations."""
    th = pytest.importorskip("torch")
    ppo = pytest.importorskip("stable_baselines3")
    obs = _recorded_observations()
    policy = load_policy(SHIPPED)
    with np.load(SHIPPED / "policy.npz") as w, np.load(SHIPPED / "obs_norm.npz") as n:
        weights = {k: th.as_tensor(w[k]) for k in w.files}
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
    from agents.train import train

    train(
        dataclasses.replace(
            config, run_dir=str(run_dir), resume=True, total_timesteps=256, **changes
        )
    )


def _checkpoint_cases() -> dict[str, tuple[Callable[[Path, bytes], None], str]]:
    def write(name: str, data: Callable[[Path, bytes], bytes]) -> Callable[[Path, bytes], None]:
        return lambda ck, evil: (ck / name).write_bytes(data(ck, evil))

    def object_arrays(ck: Path, evil: bytes) -> bytes:
        buffer = io.BytesIO()
        np.savez(buffer, obs_mean=np.array([_Payload(ck.parents[2] / "MARKER")] * 11))
        return buffer.getvalue()

    def training(change: Callable[[dict[str, Any], bytes], None]) -> Callable[[Path, bytes], None]:
        def mutate(ck: Path, evil: bytes) -> None:
            record = json.loads((ck / "training.json").read_text())
            change(record, evil)
            (ck / "training.json").write_text(json.dumps(record))

        return mutate

    def bomb(ck: Path, evil: bytes) -> bytes:
        with zipfile.ZipFile(ck / "training_state.npz") as archive:
            names = archive.namelist()
        return _zip_entries(
            [(names[0], _npy_header_only((64, 11)) + bytes(30_000_000), zipfile.ZIP_DEFLATED)]
        )

    return {
        "training_state.npz is a pickle": (
            write("training_state.npz", lambda ck, e: e),
            r"training_state.npz' is not valid training state .*File is not a zip file",
        ),
        "training_state.npz zip bomb": (
            write("training_state.npz", bomb),
            r"training_state.npz': its entries declare \d+ bytes uncompressed: .*zip bomb",
        ),
        "vecnormalize.npz object arrays": (
            write("vecnormalize.npz", object_arrays),
            r"vecnormalize.npz': array obs_mean has dtype object: allowed float32 or float64",
        ),
        "vecnormalize.npz is a pickle": (
            write("vecnormalize.npz", lambda ck, e: e),
            r"vecnormalize.npz' is not valid VecNormalize statistics .*not a zip file",
        ),
        "training.json :serialized:": (
            training(lambda r, e: r.__setitem__(":serialized:", base64.b64encode(e).decode())),
            r"training.json': field :serialized: is not known: allowed fields are format, "
            r"num_timesteps, n_updates, optimizer_state",
        ),
        "training.json huge number": (
            training(lambda r, e: r.__setitem__("num_timesteps", 10**40)),
            rf"training.json': field num_timesteps = {10**40} is out of range: allowed an "
            r"integer in \[0, 9007199254740992\]",
        ),
        "training.json NaN": (
            lambda ck, evil: (ck / "training.json").write_text(
                '{"format": 2, "num_timesteps": NaN}'
            ),
            r"training.json' is not valid JSON: the non-finite number NaN is not allowed",
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
    with pytest.raises(ValueError, match=message) as info:
        _resume(finished_run, run_dir)
    assert "\n" not in str(info.value)


def test_checkpoint_of_other_settings_names_the_array(finished_run: Any, tmp_path: Path) -> None:
    run_dir = tmp_path / "run"
    shutil.copytree(finished_run.resolved_run_dir(), run_dir)
    with pytest.raises(
        ValueError,
        match=r"training_state.npz': array policy/mlp_extractor.policy_net.0.weight has shape "
        r"\(64, 11\): expected \(32, 11\)",
    ):
        _resume(finished_run, run_dir, net_arch=[32, 32])


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
