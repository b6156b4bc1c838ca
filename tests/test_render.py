"""Tests of rendering: ``drill_env.render`` frames and the env's ``render_mode`` wiring."""

from __future__ import annotations

import importlib.util
import math
import subprocess
import sys
import warnings
from pathlib import Path
from typing import Any

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.utils.env_checker import check_env

import drill_env  # noqa: F401  (registers DrillString-v0)
from drill_env import render
from drill_env.env import DrillStringEnv
from drill_env.render import History, StringRenderer, dial_nodes, node_angles

ENV_ID = "DrillString-v0"
STUCK_RGB = (214, 39, 40)  # the renderer's stuck colour, #d62728
SLIP_RGB = (44, 160, 44)  # the renderer's slipping colour, #2ca02c
ROOT = Path(__file__).resolve().parents[1]


def make(**kwargs: Any) -> gym.Env[Any, Any]:
    """A deterministic env (no randomisation, no noise) in rgb_array mode."""
    kwargs = {"randomize": False, "noise_std_rad_s": 0.0, "render_mode": "rgb_array", **kwargs}
    return gym.make(ENV_ID, **kwargs)


def colour_pixels(frame: np.ndarray, rgb: tuple[int, int, int], tol: int = 12) -> int:
    """Pixels of ``frame`` within ``tol`` of ``rgb`` on every channel."""
    diff = np.abs(frame.astype(np.int16) - np.array(rgb, dtype=np.int16))
    return int(np.count_nonzero(np.all(diff <= tol, axis=-1)))


def filled_history(n_nodes: int, stuck: bool, samples: int = 100) -> History:
    """A history of an ``n_nodes`` string turning at 10 rad/s with constant twists."""
    h = History(n_nodes, samples + 2)
    x = np.zeros(2 * n_nodes - 1)
    x[0::2] = 10.0
    x[1::2] = np.linspace(1.0, 3.0, n_nodes - 1)
    for k in range(samples):
        h.append(0.05 * k, x, 12e3, 10.0, 97e3, stuck)
    return h


# ----------------------------------------------------------------------- frames, env
def test_frame_shape_and_dtype() -> None:
    """render() returns an (H, W, 3) uint8 frame after reset and after steps."""
    env = make()
    env.reset(seed=0)
    frame = env.render()
    assert isinstance(frame, np.ndarray)
    assert frame.dtype == np.uint8
    assert frame.shape == (480, 800, 3)
    for _ in range(5):
        env.step(np.array([0.2], dtype=np.float32))
    again = env.render()
    assert isinstance(again, np.ndarray)
    assert again.shape == (480, 800, 3) and again.dtype == np.uint8
    assert again.std() > 10  # a picture, not a blank canvas
    env.close()


def test_frames_change_as_the_string_turns() -> None:
    """Under the proposed SMC the string winds up and turns: frames one second apart differ,
    in the dials (left third) as well as in the traces."""
    env = make(base_controller="proposed")
    env.reset(seed=0)
    zero = np.zeros(1, dtype=np.float32)
    frames = []
    for _ in range(3):
        for _ in range(20):
            env.step(zero)
        frames.append(env.render())
    for a, b in zip(frames, frames[1:], strict=False):
        assert isinstance(a, np.ndarray) and isinstance(b, np.ndarray)
        changed = np.any(a != b, axis=-1)
        assert changed[:, : 800 // 3].sum() > 200  # the dials moved
        assert changed[:, 800 // 3 :].sum() > 200  # the traces moved
    env.close()


def test_render_history_restarts_at_reset_and_is_bounded() -> None:
    """The history holds the last ~20 s: reset clears it, steps fill it up to its capacity."""
    env = make(episode_s=40.0, control_dt_s=0.1)
    env.reset(seed=0)
    rendering = env.unwrapped._rendering  # type: ignore[attr-defined]
    assert len(rendering.history) == 1
    for _ in range(300):  # 30 s
        env.step(np.array([0.0], dtype=np.float32))
    capacity = render.history_capacity(render.WINDOW_S, 0.1)
    assert len(rendering.history) == capacity == 202
    times = rendering.history.arrays().time_s
    assert times[-1] == pytest.approx(30.0)
    assert np.all(np.diff(times) > 0)
    assert times[-1] - times[0] >= render.WINDOW_S
    env.reset(seed=1)
    assert len(rendering.history) == 1
    env.close()


def test_stuck_marker_follows_the_env() -> None:
    """At rest the bit sticks (red STUCK marker); once the SMC breaks it away it slips
    (green SLIPPING marker). The marker is checked in pixels against info["bit_stuck"]."""
    env = make(base_controller="proposed")
    _, info = env.reset(seed=0)
    assert info["bit_stuck"]
    frame = env.render()
    assert isinstance(frame, np.ndarray)
    assert colour_pixels(frame, STUCK_RGB) > 1000
    assert colour_pixels(frame, SLIP_RGB) < 50
    zero = np.zeros(1, dtype=np.float32)
    for _ in range(600):
        _, _, _, _, info = env.step(zero)
        if not info["bit_stuck"]:
            break
    assert not info["bit_stuck"], "the bit never broke away in 30 s"
    frame = env.render()
    assert isinstance(frame, np.ndarray)
    assert colour_pixels(frame, SLIP_RGB) > 1000
    assert colour_pixels(frame, STUCK_RGB) < colour_pixels(frame, SLIP_RGB) / 4
    env.close()


@pytest.mark.parametrize("stuck", [True, False])
def test_stuck_marker_follows_the_history(stuck: bool) -> None:
    """The renderer marks the bit from the last sample's stuck flag alone."""
    frame = StringRenderer(4).frame(filled_history(4, stuck))
    on, off = (STUCK_RGB, SLIP_RGB) if stuck else (SLIP_RGB, STUCK_RGB)
    assert colour_pixels(frame, on) > 1000
    assert colour_pixels(frame, off) < 50


def test_many_nodes_draw_a_subset_of_dials() -> None:
    """A 100-node string draws (6 dials, every segment in the strip) and its frame follows
    its state."""
    assert dial_nodes(4) == [0, 1, 2, 3]
    nodes = dial_nodes(100)
    assert len(nodes) == render.MAX_DIALS and nodes[0] == 0 and nodes[-1] == 99
    renderer = StringRenderer(100)
    a = renderer.frame(filled_history(100, stuck=False))
    h = filled_history(100, stuck=False)
    x = np.zeros(199)
    x[0::2] = 10.0
    x[1::2] = 0.5  # the twists change
    h.append(5.0, x, 12e3, 10.0, 97e3, False)
    b = renderer.frame(h)
    assert a.shape == b.shape == (480, 800, 3)
    assert np.any(a != b)


# ----------------------------------------------------------------------- kinematics
def test_node_angles_from_twists() -> None:
    """phi_k = phi_0 - sum of the twists above it: a hand-made string comes back exactly."""
    phi = np.array([5.0, 3.0, 2.5, 1.0])
    state = np.array([1.0, phi[0] - phi[1], 2.0, phi[1] - phi[2], 3.0, phi[2] - phi[3], 4.0])
    np.testing.assert_allclose(node_angles(state, phi[0]), phi, rtol=0, atol=1e-15)
    stacked = node_angles(np.stack([state, state]), np.array([phi[0], phi[0] + 1.0]))
    np.testing.assert_allclose(stacked[1], phi + 1.0, rtol=0, atol=1e-15)


def test_history_integrates_the_top_drive_angle() -> None:
    """The top-drive angle is the integral of its speed: exact for a linear ramp
    (trapezoidal rule), and for w = 10 + 3 sin(t) sampled at h = 50 ms within the trapezoidal
    error h^2 / 12 |w'(T) - w'(0)| = 3.7e-4 rad of the closed form 10 t + 3 (1 - cos t)."""
    ramp = History(2, 500)
    sine = History(2, 500)
    for k in range(401):
        t = 0.05 * k
        ramp.append(t, [2.0 * t, 0.0, 0.0], 0.0, 0.0, 1.0, False)
        sine.append(t, [10.0 + 3.0 * math.sin(t), 0.0, 0.0], 0.0, 0.0, 1.0, False)
    t_end = 0.05 * 400
    assert ramp.arrays().top_drive_angle_rad[-1] == pytest.approx(t_end**2, abs=1e-9)
    expected = 10.0 * t_end + 3.0 * (1.0 - math.cos(t_end))
    bound = 0.05**2 / 12 * abs(3.0 * math.cos(t_end) - 3.0)
    assert abs(sine.arrays().top_drive_angle_rad[-1] - expected) < 1.05 * bound


def test_history_ring_buffer_keeps_the_newest_samples_in_order() -> None:
    """Past its capacity the history drops the oldest samples and stays in time order."""
    h = History(2, 5)
    for k in range(12):
        h.append(float(k), [float(k), 0.0, 0.0], 0.0, 0.0, 1.0, k % 2 == 0)
    a = h.arrays()
    np.testing.assert_array_equal(a.time_s, [7.0, 8.0, 9.0, 10.0, 11.0])
    np.testing.assert_array_equal(a.states[:, 0], a.time_s)
    np.testing.assert_array_equal(a.bit_stuck, [False, True, False, True, False])
    h.clear()
    assert len(h) == 0 and h.arrays().time_s.size == 0


def test_empty_history_draws_a_frame() -> None:
    """A renderer given no samples still returns a frame (saying so), not an error."""
    frame = StringRenderer(4).frame(History(4, 10))
    assert frame.shape == (480, 800, 3) and frame.dtype == np.uint8


# ------------------------------------------------------------------------- bad input
@pytest.mark.parametrize("mode", ["rgb", "ansi", 3, "RGB_ARRAY"])
def test_invalid_render_mode_errors(mode: object) -> None:
    """An unknown render_mode is a ValueError listing the valid ones."""
    with pytest.raises(
        ValueError, match=r"render_mode = .* is not valid: allowed None, 'human', 'rgb_array'"
    ):
        DrillStringEnv(render_mode=mode)  # type: ignore[arg-type]
    if isinstance(mode, str):  # (gym.make itself fails on a non-string mode)
        with (
            warnings.catch_warnings(),
            pytest.raises(ValueError, match=r"render_mode = .* is not valid"),
        ):
            warnings.simplefilter("ignore")  # gym.make warns about an undeclared mode first
            gym.make(ENV_ID, render_mode=mode)


def test_renderer_bad_input_errors() -> None:
    """Wrong node counts, state shapes and sizes name the field and the allowed range."""
    with pytest.raises(ValueError, match=r"n_nodes = 1 is out of range: allowed an integer >= 2"):
        History(1, 10)
    with pytest.raises(ValueError, match=r"capacity = 1 is out of range"):
        History(4, 1)
    with pytest.raises(ValueError, match=r"state has shape \(5,\): allowed \(7,\) for 4 nodes"):
        History(4, 10).append(0.0, np.zeros(5), 0.0, 0.0, 1.0, False)
    with pytest.raises(ValueError, match=r"width_px = 10 is out of range: allowed 64..8192"):
        StringRenderer(4, width_px=10)
    with pytest.raises(ValueError, match=r"labels has 2 names: allowed one per node \(4\)"):
        StringRenderer(4, labels=["a", "b"])
    with pytest.raises(ValueError, match=r"history has 3 nodes: allowed 4"):
        StringRenderer(4).frame(History(3, 10))
    with pytest.raises(ValueError, match=r"states have 4 entries per sample"):
        node_angles(np.zeros(4), 0.0)


def test_render_before_reset_and_without_mode() -> None:
    """render() before reset() is an error; without a render_mode it warns and returns None."""
    env = DrillStringEnv(render_mode="rgb_array")
    with pytest.raises(RuntimeError, match=r"call reset\(\) before render\(\)"):
        env.render()
    plain = DrillStringEnv()
    plain.reset(seed=0)
    with pytest.warns(UserWarning, match="without a render_mode"):
        assert plain.render() is None


def test_human_mode_without_display_says_so(monkeypatch: pytest.MonkeyPatch) -> None:
    """Headless, render_mode='human' fails at construction with a message that names the
    missing display and suggests rgb_array; the instance then lists only rgb_array."""
    monkeypatch.setattr(sys, "platform", "linux")
    monkeypatch.delenv("DISPLAY", raising=False)
    monkeypatch.delenv("WAYLAND_DISPLAY", raising=False)
    monkeypatch.delenv("MPLBACKEND", raising=False)
    with pytest.raises(RuntimeError, match=r"needs a display.*render_mode='rgb_array'"):
        gym.make(ENV_ID, render_mode="human")
    assert render.available_render_modes() == ["rgb_array"]
    assert DrillStringEnv().metadata["render_modes"] == ["rgb_array"]
    assert DrillStringEnv.metadata["render_modes"] == ["human", "rgb_array"]
    monkeypatch.setenv("DISPLAY", ":0")
    monkeypatch.setenv("MPLBACKEND", "Agg")
    with pytest.raises(RuntimeError, match=r"MPLBACKEND = 'agg' is non-interactive"):
        DrillStringEnv(render_mode="human")


def _tk_display_works() -> bool:
    if render.human_mode_problem() is not None or importlib.util.find_spec("tkinter") is None:
        return False
    import tkinter

    try:
        tkinter.Tk().destroy()
    except tkinter.TclError:
        return False
    return True


@pytest.mark.skipif(not _tk_display_works(), reason="human mode needs a display and Tk")
def test_human_mode_shows_a_window() -> None:
    """Where a display exists, human mode opens a window, shows every step and closes."""
    env = make(render_mode="human", control_dt_s=0.1)
    env.reset(seed=0)
    for _ in range(3):
        env.step(np.array([0.0], dtype=np.float32))
    assert env.render() is None
    window = env.unwrapped._rendering.window  # type: ignore[attr-defined]
    assert window is not None and not window.closed
    env.close()
    assert window.closed


# --------------------------------------------------------------------- env contract
def test_metadata_declares_render_modes_and_fps() -> None:
    """Both modes are declared; render_fps is one frame per decision (real-time video)."""
    assert DrillStringEnv.metadata["render_modes"] == ["human", "rgb_array"]
    assert DrillStringEnv.metadata["render_fps"] == 10  # the default 0.1 s decision period
    env = make(control_dt_s=0.05)
    assert env.metadata["render_fps"] == pytest.approx(20.0)
    assert env.render_mode == "rgb_array"
    assert "rgb_array" in env.metadata["render_modes"]


@pytest.mark.parametrize("mode", [None, "rgb_array"])
def test_gymnasium_env_checker_with_render_modes(mode: str | None) -> None:
    """Gymnasium's check_env, render check included (it renders every mode the instance
    declares), passes without a warning."""
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        env = gym.make(ENV_ID, render_mode=mode, base_controller="proposed")
        check_env(env.unwrapped)
        env.close()


def test_no_render_mode_costs_nothing() -> None:
    """Without a render_mode no history is kept and matplotlib is never imported (a fresh
    interpreter: import, make, reset, step)."""
    env = DrillStringEnv()
    assert env._rendering is None
    code = (
        "import sys, numpy as np, gymnasium as gym, drill_env\n"
        "env = gym.make('DrillString-v0')\n"
        "env.reset(seed=0)\n"
        "env.step(np.zeros(1, dtype=np.float32))\n"
        "print(sorted(m for m in sys.modules if m.split('.')[0] == 'matplotlib'))\n"
    )
    out = subprocess.run(
        [sys.executable, "-c", code], cwd=ROOT, capture_output=True, text=True, check=True
    )
    assert out.stdout.strip() == "[]"


@pytest.mark.skipif(
    importlib.util.find_spec("moviepy") is None,
    reason="RecordVideo needs moviepy: pip install -e '.[video]'",
)
def test_record_video(tmp_path: Path) -> None:
    """gymnasium.wrappers.RecordVideo writes a 2 s episode (41 frames at 20 fps) to mp4."""
    from gymnasium.wrappers import RecordVideo

    env = RecordVideo(
        make(episode_s=2.0, control_dt_s=0.05, max_episode_steps=-1),
        str(tmp_path / "videos"),
        episode_trigger=lambda episode: episode == 0,
    )
    env.reset(seed=0)
    done = False
    steps = 0
    while not done:
        _, _, terminated, truncated, _ = env.step(np.array([0.0], dtype=np.float32))
        done = terminated or truncated
        steps += 1
    env.close()
    assert steps == 40
    videos = sorted((tmp_path / "videos").glob("*.mp4"))
    assert [v.name for v in videos] == ["rl-video-episode-0.mp4"]
    from moviepy import VideoFileClip

    with VideoFileClip(str(videos[0])) as clip:
        assert clip.fps == pytest.approx(20.0)
        assert clip.duration == pytest.approx(41 / 20.0, abs=0.06)
        assert tuple(clip.size) == (800, 480)
