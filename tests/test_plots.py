"""The studies' figures (:mod:`experiments.plots`): the trace helpers, the text-collision
check, and every figure that ``compare``, ``evaluate`` and ``map`` write, built by the same
functions the commands use, on short real runs: no overlapping or cut-off text, readable
labels, every controller visible, the torque axis spanning the run.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import gymnasium as gym
import numpy as np
import pytest
from matplotlib.colors import to_hex
from matplotlib.figure import Figure

import drill_env  # noqa: F401  (registers DrillString-v0)
from drill_env.evaluation import ZeroAction, rollout
from experiments import compare, evaluate
from experiments.plots import (
    Envelope,
    downsample,
    envelope,
    learning_curves_figure,
    metric_bars_figure,
    panels_figure,
    speed_torque_figure,
    text_outside,
    text_overlaps,
    text_problems,
    time_window,
)
from experiments.stick_slip_map import compute_map, map_figure, maps_figure


@pytest.fixture(scope="module")
def short_trace():  # type: ignore[no-untyped-def]
    """1 s of CSMC in residual mode (1,000 plant steps)."""
    env = gym.make(
        "DrillString-v0",
        randomize=False,
        base_controller="csmc",
        episode_s=1.0,
        control_dt_s=0.5,
        max_episode_steps=-1,
    )
    return rollout(env, ZeroAction(), seed=0)


def texts_of(fig: Figure) -> list[str]:
    fig.canvas.draw()
    return [t.get_text() for t in fig.findobj(lambda a: hasattr(a, "get_text"))]


class TestFigureHelpers:
    """The trace helpers the figures rely on."""

    def test_downsample_keeps_chattering(self, short_trace) -> None:  # type: ignore[no-untyped-def]
        # A torque switching by +-1 kN m at every step must not alias to a flat line.
        chatter = 13_000.0 + 1_000.0 * (-1.0) ** np.arange(1000)
        small = downsample(dataclasses.replace(short_trace, torque_nm=chatter), 10)
        assert small.time_s.shape == (100,)
        assert small.plant_dt_s == pytest.approx(0.01)
        assert small.duration_s == pytest.approx(short_trace.duration_s)
        np.testing.assert_array_equal(small.torque_nm[0::2], 14_000.0)
        np.testing.assert_array_equal(small.torque_nm[1::2], 12_000.0)
        np.testing.assert_array_equal(small.bit_speed_rad_s, short_trace.bit_speed_rad_s[::10])

    def test_downsample_bad_factor(self, short_trace) -> None:  # type: ignore[no-untyped-def]
        with pytest.raises(ValueError, match=r"every = 0 is out of range"):
            downsample(short_trace, 0)

    def test_time_window(self, short_trace) -> None:  # type: ignore[no-untyped-def]
        tail = time_window(short_trace, 0.8)
        assert tail.time_s.shape == (200,)
        assert tail.time_s[0] == pytest.approx(0.8)
        np.testing.assert_array_equal(tail.torque_nm, short_trace.torque_nm[800:])

    def test_envelope_is_each_bins_min_mean_max(self, short_trace) -> None:  # type: ignore[no-untyped-def]
        rng = np.random.default_rng(0)
        torque = rng.normal(13e3, 2e3, 1000)
        band = envelope(dataclasses.replace(short_trace, torque_nm=torque), 0.1)
        bins = [torque[k : k + 100] for k in range(0, 1000, 100)]
        np.testing.assert_allclose(band.low, [b.min() for b in bins])
        np.testing.assert_allclose(band.high, [b.max() for b in bins])
        np.testing.assert_allclose(band.mean, [b.mean() for b in bins])
        np.testing.assert_allclose(band.time_s, 0.0495 + 0.1 * np.arange(10))
        # bins of 300 samples: the last one holds the 100 samples left, no padding counts
        odd = envelope(dataclasses.replace(short_trace, torque_nm=torque), 0.3)
        assert odd.time_s.shape == (4,)
        assert (odd.low[-1], odd.high[-1]) == (torque[900:].min(), torque[900:].max())
        assert odd.mean[-1] == pytest.approx(torque[900:].mean(), rel=1e-12)
        with pytest.raises(ValueError, match=r"bin_s = 0.0 is out of range"):
            envelope(short_trace, 0.0)

    def test_panel_without_traces(self, short_trace) -> None:  # type: ignore[no-untyped-def]
        with pytest.raises(ValueError, match=r"panel\(s\) 'csmc' have no traces"):
            panels_figure({"csmc": {}, "msmc": {"a": short_trace}})
        with pytest.raises(ValueError, match=r"quantity = 'power' is not valid"):
            panels_figure({"msmc": {"a": short_trace}}, quantity="power")
        with pytest.raises(ValueError, match=r"column\(s\) 'x' have no traces"):
            speed_torque_figure({"x": {}})


class TestTextCheck:
    """text_overlaps / text_outside find what they should (so a passing check means
    something)."""

    @staticmethod
    def blank() -> Figure:
        from matplotlib.backends.backend_agg import FigureCanvasAgg

        fig = Figure(figsize=(4, 3), dpi=80)
        FigureCanvasAgg(fig)
        return fig

    def test_clean_figure(self) -> None:
        fig = self.blank()
        ax = fig.add_subplot()
        ax.set_title("a title")
        ax.set_xlabel("time (s)")
        fig.subplots_adjust(bottom=0.2)
        assert text_overlaps(fig) == [] and text_outside(fig) == []

    def test_two_texts_on_top_of_each_other(self) -> None:
        fig = self.blank()
        fig.text(0.5, 0.5, "first text")
        fig.text(0.52, 0.51, "second text")
        assert text_overlaps(fig) == ["'first text' overlaps 'second text'"]

    def test_crowded_tick_labels_of_one_axis(self) -> None:
        fig = self.blank()
        ax = fig.add_subplot()
        ax.set_xticks(range(12), [f"controller {k}" for k in range(12)])
        problems = text_overlaps(fig)
        assert problems and all("tick label" in p for p in problems)
        assert "tick label 'controller 0' (axes 0 x) overlaps tick label 'controller 1'" in (
            " ".join(problems)
        )

    def test_hidden_and_out_of_view_texts_do_not_count(self) -> None:
        fig = self.blank()
        ax = fig.add_subplot()
        ax.set_xlim(0, 1)
        fig.text(0.5, 0.5, "visible")
        fig.text(0.5, 0.5, "hidden").set_visible(False)
        other = fig.add_axes((0.1, 0.1, 0.3, 0.3))
        other.set_title("in a hidden axes")
        other.set_visible(False)
        assert text_overlaps(fig) == []

    def test_text_cut_off_by_the_edge(self) -> None:
        fig = self.blank()
        fig.text(0.9, 0.5, "this text runs off the right edge")
        assert text_outside(fig) == [
            "'this text runs off the right edge' reaches beyond the figure"
        ]


# ------------------------------------------------------------ every figure of the commands
@pytest.fixture(scope="module")
def comparison() -> tuple[list[dict[str, Any]], dict[tuple[str, str, float], Any]]:
    """The default comparison (every controller, the shipped agent, four conditions, two
    noise levels), 6 s runs."""
    return compare.run_comparison(
        compare.default_controllers(),
        list(compare.CONDITIONS),
        [0.0, 0.1],
        duration_s=6.0,
        agent=compare.load_agent(),
        progress=False,
    )


@pytest.fixture(scope="module")
def comparison_figures(comparison: Any) -> dict[str, Figure]:
    return dict(compare.comparison_figures(*comparison))


@pytest.fixture(scope="module")
def heldout_figures() -> dict[str, Figure]:
    """The figures of ``drill-gym evaluate``: the shipped agents and their base controller
    on all 20 held-out scenarios."""
    agents = [evaluate.load_policy(p) for p in evaluate.shipped_models()]
    agents = [a for a in agents if a.env_id == "DrillString-v0"]  # not the field agent
    labels = ["proposed", *(a.name for a in agents)]
    rows, traces = evaluate.evaluate(agents, ["proposed"], keep_traces=labels)
    return dict(evaluate.heldout_figures(rows, traces, labels))


@pytest.fixture(scope="module")
def map_figures() -> dict[str, Figure]:
    """The figures of ``drill-gym map`` (one map and the maps side by side, a 1-cell map)."""
    grid = dict(duration_s=4.0, window_s=2.0, progress=False)
    maps = [
        compute_map(name, [40e3, 120e3, 200e3], [1.0, 8.0, 16.0], **grid)  # type: ignore[arg-type]
        for name in ("stiff_pi", "soft_speed", "z_torque", "proposed")
    ]
    single = compute_map("csmc", [1e5], [5.0], **grid)  # type: ignore[arg-type]
    return {
        "stick_slip_map_stiff_pi.png": map_figure(maps[0]),
        "stick_slip_maps.png": maps_figure(maps),
        "stick_slip_map_csmc.png": map_figure(single),
    }


def test_the_comparison_writes_every_figure(comparison_figures: dict[str, Figure]) -> None:
    names = [f"speed_torque_{c}.png" for c in (*compare.default_controllers(), "residual_ppo")]
    names += ["noise_speed_torque.png", "noise_torque_zoom.png", "adaptive_gains.png"]
    names += [f"bars_{m}.png" for m in ("rmse", "ise_iae", "rmsd", "chattering")]
    assert sorted(comparison_figures) == sorted(names)


def _all_figures(
    comparison_figures: dict[str, Figure],
    heldout_figures: dict[str, Figure],
    map_figures: dict[str, Figure],
) -> Iterator[tuple[str, Figure]]:
    for group, figures in (
        ("compare", comparison_figures),
        ("evaluate", heldout_figures),
        ("map", map_figures),
    ):
        for name, fig in figures.items():
            yield f"{group}/{name}", fig


def test_no_text_overlaps_or_is_cut_off_in_any_figure(
    comparison_figures: dict[str, Figure],
    heldout_figures: dict[str, Figure],
    map_figures: dict[str, Figure],
    tmp_path: Path,
) -> None:
    assert len(heldout_figures) == 7 and len(map_figures) == 3
    runs = tmp_path / "runs"
    for label, steps in (("residual_ppo", 3), ("direct_ppo", 2)):
        (runs / label).mkdir(parents=True)
        (runs / label / "validation.csv").write_text(
            "timesteps,iae_ratio,rmsd_ratio,severity_ratio,score\n"
            + "".join(f"{k * 100_000},{1 - 0.1 * k},{1 - 0.01 * k},0.9,0.5\n" for k in range(steps))
        )
        (runs / label / "progress.csv").write_text(
            "time/total_timesteps,rollout/ep_rew_mean\n16000,-500\n32000,-400\n"
        )
    curves = learning_curves_figure(
        {"residual": runs / "residual_ppo", "direct": runs / "direct_ppo"}, "learning curves"
    )
    problems = {
        name: text_problems(fig)
        for name, fig in [
            *_all_figures(comparison_figures, heldout_figures, map_figures),
            ("learning curves", curves),
        ]
    }
    assert {name: p for name, p in problems.items() if p} == {}


def test_labels_are_readable(
    comparison_figures: dict[str, Figure],
    heldout_figures: dict[str, Figure],
    map_figures: dict[str, Figure],
) -> None:
    for name, fig in _all_figures(comparison_figures, heldout_figures, map_figures):
        for text in texts_of(fig):
            for raw in ("noise_std_rad_s", "stick_slip_severity", "rmsd_nm", "_rad_s", "Table 3"):
                assert raw not in text, (name, text)


def _legend_texts(fig: Figure) -> list[str]:
    legends = [*fig.legends, *(ax.get_legend() for ax in fig.axes)]
    return [t.get_text() for legend in legends if legend is not None for t in legend.get_texts()]


def test_noise_figure_shows_every_controller(comparison_figures: dict[str, Figure]) -> None:
    fig = comparison_figures["noise_speed_torque.png"]
    labels = _legend_texts(fig)
    for name in (*compare.default_controllers(), "residual_ppo"):
        assert name in labels
    legends = [ax.get_legend() for ax in fig.axes if ax.get_legend() is not None]
    titles = [legend.get_title().get_text() for legend in legends]
    assert titles == [
        "the paper's sliding-mode controllers",
        "industry speed loops",
        "learned agent",
    ]
    # each torque panel spans its own run: the band of z_torque / stiff_pi does not set the
    # SMC column's axis
    smc_torque_axis = fig.axes[3]
    assert smc_torque_axis.get_ylim()[1] < 30.0


def test_torque_axis_spans_the_run_and_marks_the_start_up_peak(
    comparison: Any, comparison_figures: dict[str, Figure]
) -> None:
    _, runs = comparison
    fig = comparison_figures["speed_torque_stiff_pi.png"]
    ax_torque = fig.axes[1]
    top = ax_torque.get_ylim()[1]
    assert top < 45.0  # the 50 kN m start-up peak does not set the axis
    for condition in compare.CONDITIONS:
        band: Envelope = runs[("stiff_pi", condition, 0.0)].torque
        late = band.time_s >= 1.0
        assert band.high[late].max() / 1e3 <= top  # everything after the first second shows
    assert any(text.startswith("off the axis at start-up (up to 50") for text in _legend_texts(fig))


def test_adaptive_gains_are_told_apart(comparison_figures: dict[str, Figure]) -> None:
    fig = comparison_figures["adaptive_gains.png"]
    ax = fig.axes[0]
    lines = [line for line in ax.get_lines() if len(line.get_xdata()) > 1]
    styles = [(to_hex(line.get_color()), str(line.get_linestyle())) for line in lines]
    assert len(lines) == 12  # asmc, proposed and the agent's proposed, four conditions each
    assert len(set(styles)) == len(styles)
    assert ax.get_ylabel() == "adaptive gain k (N m)"
    assert "adaptive switching gain k" in ax.get_title()


def test_small_rmsd_differences_show(comparison_figures: dict[str, Figure]) -> None:
    fig = comparison_figures["bars_rmsd.png"]
    ax = fig.axes[0]
    low, high = ax.get_xlim()
    assert low > 5_000  # a fitted axis, not one from zero
    changes = [t.get_text() for t in ax.texts]
    assert len(changes) == len(compare.default_controllers()) + 1
    assert all(text.endswith(" %") and text[0] in "+-" for text in changes)
    assert fig.legends[0].get_title().get_text() == "measurement noise"
    assert {t.get_text() for t in fig.legends[0].get_texts()} == {"noise off", "noise 0.1 rad/s"}


def test_heldout_panels_say_what_they_show(heldout_figures: dict[str, Figure]) -> None:
    fig = heldout_figures["heldout_bit_speed.png"]
    visible = [ax for ax in fig.axes if ax.get_visible()]
    assert len(visible) == 20
    assert visible[1].get_title() == "h02: V_ref 4 rad/s, condition1\nWOB 120 -> 180 kN at 50 s"
    assert all(ax.get_legend() is None for ax in visible) and len(fig.legends) == 1
    assert "reference" in _legend_texts(fig)
    for ax in visible:  # the reference line in every panel
        assert any(to_hex(line.get_color()) == "#000000" for line in ax.get_lines())
    bars = heldout_figures["heldout_iae_severity.png"]
    assert len(bars.legends) == 1
    assert [t.get_text() for t in bars.axes[-1].get_xticklabels()][:2] == ["h01", "h02"]


def test_maps_explain_their_colours_and_line(map_figures: dict[str, Figure]) -> None:
    for fig in map_figures.values():
        colorbars = [ax for ax in fig.axes if ax.get_label() == "<colorbar>"]
        assert colorbars and all(ax.get_ylabel() for ax in colorbars)
        assert any("boundary of stick-slip" in t for t in _legend_texts(fig))


def test_bars_of_many_long_names_have_readable_labels() -> None:
    """The field comparison's bar charts: 17 runs labelled controller (observation), without and
    with noise, on linear and log value axes, without overlapping or clipped labels."""
    modes = ("state", "surface")
    labels = [f"{c} ({m})" for c in compare.default_controllers() for m in modes][:17]
    rng = np.random.default_rng(0)
    rows = [
        {"controller": c, "noise_std_rad_s": noise, "rmsd_nm": x, "chattering_nm_per_s": 3 * x}
        for c in labels
        for noise, x in zip((0.0, 0.05), rng.uniform(5e3, 4e4, 2), strict=True)
    ]
    assert len(labels) == 17
    for metric, log in (("rmsd_nm", False), ("chattering_nm_per_s", True)):
        fig = metric_bars_figure(rows, metric, hue="noise_std_rad_s", log=log)
        assert not text_problems(fig), (metric, text_problems(fig))
