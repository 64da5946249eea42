"""Every Markdown link of README.md, docs/ and datasets/ to a file of the repository resolves, and so does its
#anchor (a heading of the page, as GitHub names it)."""

from __future__ import annotations

import re
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
PAGES = sorted([ROOT / "README.md", *(ROOT / "docs").rglob("*.md"), *(ROOT / "datasets").glob("*.md")])

_FENCE = re.compile(r"^(```|~~~).*?^\1", re.S | re.M)
_LINK = re.compile(r"(?<!!)\[[^\]]*\]\(([^)\s]+)(?:\s+\"[^\"]*\")?\)")


def _prose(text: str) -> str:
    """The page without its fenced code blocks and inline code (links there are not links)."""
    return re.sub(r"`[^`\n]*`", "", _FENCE.sub("", text))


def links(text: str) -> list[str]:
    """The targets of the Markdown links (and images) of a page's prose."""
    return _LINK.findall(_prose(text)) + re.findall(r"!\[[^\]]*\]\(([^)\s]+)\)", _prose(text))


def anchors(text: str) -> set[str]:
    """The anchors GitHub gives a page's headings: lower case, punctuation but ``-`` and ``_`` dropped, spaces
    as ``-``; a repeated one gets ``-1``, ``-2`` ..."""
    seen: dict[str, int] = {}
    out = set()
    for line in _FENCE.sub("", text).splitlines():
        heading = re.match(r"#{1,6}\s+(.*?)\s*#*\s*$", line)
        if not heading:
            continue
        slug = re.sub(r"[^\w\- ]", "", heading.group(1).strip().lower()).replace(" ", "-")
        n = seen.get(slug, 0)
        seen[slug] = n + 1
        out.add(slug if n == 0 else f"{slug}-{n}")
    return out


def broken(page: Path, text: str | None = None) -> list[str]:
    """The links of ``page`` (its ``text``, default: the file's) that name no file of the repository, or no
    heading of the page they name."""
    text = page.read_text() if text is None else text
    problems = []
    for target in links(text):
        if re.match(r"[a-z][a-z0-9+.-]*:", target):  # https:, mailto: ...: not a repository path
            continue
        path, _, fragment = target.partition("#")
        if not path:  # a heading of the page itself
            if fragment not in anchors(text):
                problems.append(f"{target}: no such heading")
            continue
        resolved = (page.parent / path).resolve()
        name = resolved.relative_to(ROOT).as_posix() if resolved.is_relative_to(ROOT) else None
        if name is None:
            problems.append(f"{target}: outside the repository")
        elif not resolved.exists():
            problems.append(f"{target}: no such file")
        elif fragment and resolved.suffix == ".md" and fragment not in anchors(resolved.read_text()):
            problems.append(f"{target}: no heading #{fragment} in {name}")
    return problems


@pytest.mark.parametrize("page", PAGES, ids=lambda p: p.relative_to(ROOT).as_posix())
def test_every_link_resolves(page):
    assert broken(page) == []


def test_the_checker_finds_broken_links_and_anchors():
    assert len(PAGES) >= 15
    text = ("# A page\n\n## Its `part`: two\n\n[ok](#its-part-two) [ok](../README.md) [ok](configuration.md#ranges)\n"
            "[bad](#nowhere) [bad](missing.md) [bad](configuration.md#nowhere) [bad](../../outside.md)\n"
            "![bad](figure.png) [skipped](https://example.org) `[skipped](missing.md)`\n"
            "```\n[skipped](missing.md)\n```\n")
    found = broken(ROOT / "docs" / "a-page.md", text)
    assert [f.split(":")[0] for f in found] == ["#nowhere", "missing.md", "configuration.md#nowhere",
                                                "../../outside.md", "figure.png"]
    assert anchors("# A\n## A\n## A\n") == {"a", "a-1", "a-2"}
