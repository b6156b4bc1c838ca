"""The README and ``docs/``: every relative link resolves, nothing points outside the
repository, the README stays short, and every report opens with its conclusion."""

from __future__ import annotations

import re
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
PAGES = sorted([ROOT / "README.md", *(ROOT / "docs").rglob("*.md")])
REPORTS = sorted((ROOT / "docs" / "reports").glob("*.md"))
README_MAX_CHARS = 8_000

LINK = re.compile(r"!?\[[^\]]*\]\(([^)\s]+)(?:\s+\"[^\"]*\")?\)")
"""A markdown link or image: its target."""
CODE = re.compile(r"```.*?```|`[^`\n]*`", re.DOTALL)
"""Fenced and inline code (a link-like text there is not a link)."""
FENCED = re.compile(r"```.*?```", re.DOTALL)
"""Fenced code (a line starting with ``#`` there is not a heading)."""


def _id(path: Path) -> str:
    return str(path.relative_to(ROOT))


def _anchors(page: Path) -> set[str]:
    """The anchors of a page's headings, as GitHub makes them."""
    anchors = set()
    for line in FENCED.sub("", page.read_text()).splitlines():
        if line.startswith("#"):
            title = line.lstrip("#").strip().lower()
            title = re.sub(r"[^\w\- ]", "", title)
            anchors.add(title.replace(" ", "-"))
    return anchors


def _links(page: Path) -> list[str]:
    return LINK.findall(CODE.sub("", page.read_text()))


def test_there_are_pages_and_links() -> None:
    assert len(PAGES) >= 10 and len(REPORTS) >= 6
    assert sum(len(_links(p)) for p in PAGES) > 50


@pytest.mark.parametrize("page", PAGES, ids=_id)
def test_every_relative_link_resolves(page: Path) -> None:
    broken = []
    for target in _links(page):
        if re.match(r"^[a-z][a-z0-9+.-]*:", target):  # https:, mailto:
            continue
        path, _, anchor = target.partition("#")
        file = (page.parent / path).resolve() if path else page
        if not file.exists():
            broken.append(f"{target}: no file {file}")
        elif not file.is_relative_to(ROOT):
            broken.append(f"{target}: outside the repository")
        elif anchor and file.suffix == ".md" and anchor not in _anchors(file):
            broken.append(f"{target}: no heading #{anchor} in {_id(file)}")
    assert not broken, "\n".join(broken)


@pytest.mark.parametrize("page", PAGES, ids=_id)
def test_no_text_points_outside_the_repository(page: Path) -> None:
    text = page.read_text()
    for outside in ("../shared", "/work/shared", "shared/STYLE", "SPEC section"):
        assert outside not in text, f"{_id(page)} mentions {outside}"


def test_readme_is_short() -> None:
    size = len((ROOT / "README.md").read_text())
    assert size <= README_MAX_CHARS, f"README.md has {size:,} characters"


def test_readme_says_how_to_reach_the_command_and_install() -> None:
    text = (ROOT / "README.md").read_text()
    for needed in (
        "./scripts/compare.sh", "./scripts/test.sh", "source .venv/bin/activate",
        ".venv/bin/drill-gym", "pip install .", "pip install '.[rl]'",
        "https://download.pytorch.org/whl/cpu", "'.[scale]'", "'.[video]'", "'.[zoo]'",
    ):  # fmt: skip
        assert needed in text, needed
    for model in (ROOT / "agents" / "models").iterdir():  # every shipped model is presented
        if model.is_dir():
            assert f"`{model.name}`" in text, model.name


@pytest.mark.parametrize("report", REPORTS, ids=_id)
def test_each_report_opens_with_its_conclusion(report: Path) -> None:
    """The first paragraph after the title is the conclusion."""
    paragraphs = [p.strip() for p in report.read_text().split("\n\n") if p.strip()]
    assert paragraphs[0].startswith("# "), _id(report)
    assert paragraphs[1].startswith("**Conclusion.**"), _id(report)


def _text_files() -> list[Path]:
    folders = ("drill_env", "baselines", "agents", "experiments", "examples", "benchmarks")
    files = [ROOT / "README.md", ROOT / "pyproject.toml", *ROOT.glob("scripts/*.sh")]
    files += [p for folder in (*folders, "docs", "tests") for p in (ROOT / folder).rglob("*")]
    return [p for p in files if p.suffix in {".py", ".md", ".toml", ".sh", ".yml", ".json"}]


def test_every_docs_path_named_in_the_repository_exists() -> None:
    """A page named in code or text (``docs/specification.md``, a report) exists."""
    named = re.compile(r"(?<![\w/.])docs/[\w/.-]+\.(?:md|png)")
    missing = sorted(
        f"{_id(path)}: {hit}"
        for path in _text_files()
        for hit in named.findall(path.read_text(errors="replace"))
        if not (ROOT / hit).exists()
    )
    assert not missing, "\n".join(missing)


def test_the_readme_example_runs(capsys: pytest.CaptureFixture[str]) -> None:
    """The README's Python example, as written, prints the metrics of the paper's SMC."""
    text = (ROOT / "README.md").read_text()
    blocks = re.findall(r"```python\n(.*?)```", text, flags=re.DOTALL)
    assert len(blocks) == 1 and len(blocks[0].splitlines()) <= 12
    exec(compile(blocks[0], "README.md", "exec"), {"__name__": "readme_example"})
    printed = capsys.readouterr().out
    assert "'iae':" in printed and "'diverged': False" in printed
