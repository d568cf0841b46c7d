"""Every relative link and image in README.md, CHANGELOG.md and docs/ (studies included) points at a
file of the repository, and every #anchor at a heading of the page it names (GitHub's heading ids)."""

from __future__ import annotations

import re
import unicodedata

import pytest
from conftest import ROOT

PAGES = [ROOT / "README.md", ROOT / "CHANGELOG.md", *sorted((ROOT / "docs").rglob("*.md"))]
LINK = re.compile(r"!?\[(?:[^\]\\]|\\.)*\]\(([^)\s]+)(?:\s+\"[^\"]*\")?\)")
FENCE = re.compile(r"^(```|~~~).*?^\1", re.M | re.S)
CODE = re.compile(r"(`+)(?:(?!\1).)+?\1", re.S)


def prose(text: str) -> str:
    """The text without fenced code blocks and inline code spans, where brackets are not links."""
    return CODE.sub("", FENCE.sub("", text))


def slug(heading: str) -> str:
    """GitHub's id of a heading: lower case, punctuation dropped, spaces as hyphens."""
    text = re.sub(r"`|\*\*|\[([^\]]*)\]\([^)]*\)", r"\1", heading.strip()).lower()
    kept = "".join(c for c in text if c in " -_" or unicodedata.category(c)[0] in "LN")
    return kept.replace(" ", "-")


def anchors(path) -> set[str]:
    seen: dict[str, int] = {}
    out = set()
    for line in FENCE.sub("", path.read_text(encoding="utf-8")).splitlines():
        m = re.match(r"#{1,6}\s+(.*?)\s*#*\s*$", line)
        if m:
            base = slug(m.group(1))
            n = seen.get(base, 0)
            seen[base] = n + 1
            out.add(base if n == 0 else f"{base}-{n}")
    return out


def links(page) -> list[str]:
    return [t for t in LINK.findall(prose(page.read_text(encoding="utf-8")))
            if not re.match(r"^[a-z][a-z0-9+.-]*:", t)]       # http:, https:, mailto: are not checked


def broken(page, root=ROOT) -> list[str]:
    bad = []
    for target in links(page):
        path, _, anchor = target.partition("#")
        dest = (page.parent / path).resolve() if path else page
        if not dest.exists():
            bad.append(f"{target}: no such file")
        elif anchor and dest.suffix == ".md" and anchor not in anchors(dest):
            bad.append(f"{target}: no heading #{anchor} in {dest.relative_to(root)}")
        elif root not in dest.parents:
            bad.append(f"{target}: outside the repository")
    return bad


@pytest.mark.parametrize("page", PAGES, ids=lambda p: str(p.relative_to(ROOT)))
def test_every_relative_link_resolves(page):
    assert broken(page) == []


def test_the_pages_hold_relative_links():
    """The pattern still finds the links the pages give (the check above is not empty)."""
    assert sum(len(links(p)) for p in PAGES) > 100
    assert any("studies/" in t for t in links(ROOT / "README.md"))


def test_the_check_finds_a_broken_link_and_anchor(tmp_path):
    page = tmp_path / "page.md"
    (tmp_path / "other.md").write_text("# Other\n\n## The `fit` (a, b)\n\n## Twice\n\n## Twice\n")
    page.write_text("[a](other.md#the-fit-a-b) [b](other.md#twice-1) [c](missing.md) [d](other.md#nope)\n"
                    "`[e](missing2.md)` and\n```\n[f](missing3.md)\n```\n[g](https://example.org/x)\n")
    assert broken(page, tmp_path) == ["missing.md: no such file", "other.md#nope: no heading #nope in other.md"]
