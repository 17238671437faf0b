"""The README and docs/: short enough for a user, every relative link lands on a file of the
repository, and nothing cites a document that is not in it."""

import re
import subprocess
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
PAGES = [
    ROOT / "README.md",
    *sorted((ROOT / "docs").glob("*.md")),
    ROOT / "benchmarks" / "README.md",
]
LINK = re.compile(r"\]\(([^)#\s]+)(#[^)\s]*)?\)")


def prose_lines(text: str) -> list[str]:
    """The lines of a Markdown page a reader reads as running text: not in a fenced or
    indented code block, not a table row, not an image."""
    lines, fenced = [], False
    for line in text.splitlines():
        if line.startswith("```"):
            fenced = not fenced
        elif not (fenced or line.startswith(("    ", "|", "!["))):
            lines.append(line)
    return lines


def test_readme_is_for_users_and_short():
    """Short in words and in lines a reader scrolls, its prose wrapped: a line budget alone
    was once kept by lines of 1 000 characters."""
    readme = (ROOT / "README.md").read_text()
    assert len(readme.split()) <= 3000
    assert len(readme.splitlines()) <= 300
    assert [row for row in readme.splitlines() if row.startswith("|") and len(row) > 240] == []
    first_commands = [line.strip() for line in readme.splitlines() if line.startswith("    ")][:2]
    assert first_commands[0].endswith(".venv/bin/pytest")
    assert first_commands[1].endswith("bilba plan peg-in-hole")


@pytest.mark.parametrize("page", PAGES, ids=lambda page: str(page.relative_to(ROOT)))
def test_prose_is_wrapped(page):
    assert [line for line in prose_lines(page.read_text()) if len(line) > 100] == []


def test_every_relative_link_resolves():
    broken = []
    for page in PAGES:
        for target, _ in LINK.findall(page.read_text()):
            if re.match(r"[a-z]+://", target):
                continue
            if not (page.parent / target).exists():
                broken.append(f"{page.relative_to(ROOT)} -> {target}")
    assert broken == []


def test_no_file_cites_a_document_outside_the_repository():
    tracked = subprocess.run(
        ["git", "ls-files"], cwd=ROOT, capture_output=True, text=True, check=True
    ).stdout.split()
    outside = re.compile(r"\.\./shared|(?<![\w/])(DESIGN|PHYSICS|STYLE)\.md")
    hits = [
        name
        for name in tracked
        if name.endswith((".py", ".md", ".yaml", ".toml", ".txt"))
        and (ROOT / name).is_file()
        and outside.search((ROOT / name).read_text(errors="replace"))
    ]
    assert hits == []
