"""Command lines generated from frozen Spec dataclasses (experiments.spec_cli)."""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field
from pathlib import Path

import pytest

from experiments.spec_cli import option, option_name, spec_from_args, spec_parser
from experiments.sweep import RunnerSpec


@dataclass(frozen=True)
class ExampleSpec:
    duration_s: float = field(
        default=150.0,
        metadata=option(low=0.0, high=1e5, open_low=True, unit="s", aliases=("--duration",)),
    )
    """length of every run, s"""
    controllers: tuple[str, ...] = field(
        default=("csmc", "proposed"), metadata=option(choices=("csmc", "proposed", "pi"))
    )
    """controllers to run"""
    seeds: tuple[int, ...] = field(default=(0,), metadata=option(low=0, high=10))
    """reset seeds"""
    out: Path = Path("results")
    """output folder"""
    label: str | None = None
    """a name for the run"""
    plots: bool = True
    """draw the figures"""
    no_progress: bool = False
    """no progress bar"""

    def __post_init__(self) -> None:
        if "pi" in self.controllers and self.duration_s < 1.0:
            raise ValueError("--duration-s: pi needs at least 1 s")


def parse(*argv: str) -> ExampleSpec:
    parser = spec_parser("drill-gym example", "an example", ExampleSpec, RunnerSpec)
    return spec_from_args(ExampleSpec, parser.parse_args(list(argv)))


def test_defaults_are_the_spec_defaults() -> None:
    assert parse() == ExampleSpec()


def test_values_parse_into_the_spec() -> None:
    spec = parse(
        "--duration-s", "2.5", "--controllers", "pi", "csmc", "--seeds", "3", "4",
        "--out", "x/y", "--label", "run", "--no-plots", "--no-progress",
    )  # fmt: skip
    assert spec == ExampleSpec(
        duration_s=2.5,
        controllers=("pi", "csmc"),
        seeds=(3, 4),
        out=Path("x/y"),
        label="run",
        plots=False,
        no_progress=True,
    )
    assert isinstance(spec.controllers, tuple) and isinstance(spec.seeds[0], int)


def test_old_name_is_accepted_and_not_shown() -> None:
    assert parse("--duration", "3").duration_s == 3.0
    text = spec_parser("p", "", ExampleSpec).format_help()
    assert "--duration-s" in text and "--duration " not in text and "--duration," not in text


@pytest.mark.parametrize(
    ("argv", "words"),
    [
        (["--duration-s", "0"], ["--duration-s", "(0, 100000] s"]),
        (["--duration-s", "1e400"], ["--duration-s", "out of range"]),
        (["--seeds", "11"], ["--seeds", "[0, 10]"]),
        (["--seeds", "1.5"], ["--seeds", "not an integer"]),
        (["--controllers", "smc"], ["--controllers", "invalid choice"]),
        (["--workers", "0"], ["--workers", "[1, 4096]"]),
        (["--bogus"], ["unrecognized arguments: --bogus"]),
    ],
)
def test_bad_values_are_one_line_with_exit_code_2(
    argv: list[str], words: list[str], capsys: pytest.CaptureFixture[str]
) -> None:
    with pytest.raises(SystemExit) as exc:
        parse(*argv)
    assert exc.value.code == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1
    for word in words:
        assert word in err


def test_spec_checks_run_when_built() -> None:
    with pytest.raises(ValueError, match="--duration-s"):
        parse("--controllers", "pi", "--duration-s", "0.5")


def test_help_shows_docstrings_units_and_defaults() -> None:
    text = spec_parser("p", "", ExampleSpec, RunnerSpec).format_help()
    assert "length of every run, s (default: 150)" in " ".join(text.split())
    assert "--no-plots" in text and "--plots" not in text
    assert "sweeps (Ray: the scale extra)" in text


def test_every_field_has_an_option() -> None:
    text = spec_parser("p", "", ExampleSpec, RunnerSpec).format_help()
    for spec_class in (ExampleSpec, RunnerSpec):
        for f in dataclasses.fields(spec_class):
            name = option_name(f.name)
            if f.default is True:
                name = "--no-" + name[2:]
            assert name in text, name


def test_runner_spec_reads_what_the_options_ask() -> None:
    parser = spec_parser("p", "", ExampleSpec, RunnerSpec)
    runner = spec_from_args(RunnerSpec, parser.parse_args([]))
    assert not runner.requested and not runner.backend().distributed
    assert runner.results_path(Path("d.sqlite")) is None
    runner = spec_from_args(RunnerSpec, parser.parse_args(["--workers", "2"]))
    assert runner.requested and runner.backend().workers == 2
    assert runner.results_path(Path("d.sqlite")) == Path("d.sqlite")


@dataclass(frozen=True)
class PositionalSpec:
    policies: tuple[str, ...] = field(
        default=(), metadata=option(positional=True, metavar="POLICY")
    )
    """what to score"""
    grid: tuple[str, ...] = field(default=(), metadata=option(repeat=True, metavar="NAME=V1,V2"))
    """a setting's values"""
    suites: tuple[str, ...] = field(
        default=("a",), metadata=option(choices=("a", "b", "c"), metavar="SUITE")
    )
    """suites to run"""


def test_positional_repeatable_and_named_choices() -> None:
    parser = spec_parser("p", "", PositionalSpec)
    spec = spec_from_args(
        PositionalSpec,
        parser.parse_args(["x", "y", "--grid", "lr=1,2", "--grid", "g=3", "--suites", "b", "c"]),
    )
    assert spec == PositionalSpec(policies=("x", "y"), grid=("lr=1,2", "g=3"), suites=("b", "c"))
    assert spec_from_args(PositionalSpec, parser.parse_args([])) == PositionalSpec()
    text = parser.format_help()
    assert "POLICY" in text and "SUITE" in text and "(repeatable)" in text
    with pytest.raises(SystemExit):
        parser.parse_args(["--suites", "d"])


def test_a_path_default_is_checked_like_a_given_value(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    from experiments.arguments import output_folder

    taken = tmp_path / "a_file"
    taken.write_text("not a folder")

    @dataclass(frozen=True)
    class OutSpec:
        out: Path = field(default=taken, metadata=option(parse=output_folder, metavar="DIR"))
        """output folder"""

    parser = spec_parser("p", "", OutSpec)
    with pytest.raises(SystemExit) as exc:
        parser.parse_args([])
    assert exc.value.code == 2 and "--out" in capsys.readouterr().err
    fine = spec_from_args(OutSpec, parser.parse_args(["--out", str(tmp_path / "new")]))
    assert fine.out == tmp_path / "new"
