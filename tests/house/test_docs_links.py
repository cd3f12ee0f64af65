"""Every relative link of the README and of docs/ points at a file (or folder) that exists."""

from __future__ import annotations

import re
from pathlib import Path
from urllib.parse import unquote

import pytest

REPO = Path(__file__).resolve().parents[2]

#: Markdown links and images: ``[text](target)`` / ``![alt](target "title")``; code spans are
#: removed first so that shell examples such as ``[a](b)`` inside backticks are not read as links.
LINK = re.compile(r"!?\[[^\]]*\]\(\s*<?([^)\s>]+)>?(?:\s+\"[^\"]*\")?\s*\)")
CODE = re.compile(r"```.*?```|`[^`\n]*`", re.DOTALL)


def _pages() -> list[Path]:
    return [REPO / "README.md", *sorted((REPO / "docs").rglob("*.md"))]


def _relative_targets(page: Path) -> list[str]:
    text = CODE.sub("", page.read_text(encoding="utf-8"))
    targets = []
    for target in LINK.findall(text):
        if re.match(r"^[a-z][a-z0-9+.-]*:", target, re.IGNORECASE) or target.startswith("#"):
            continue  # a URL (http:, mailto:, …) or an anchor in the same page
        targets.append(target)
    return targets


@pytest.mark.parametrize("page", _pages(), ids=lambda p: str(p.relative_to(REPO)))
def test_every_relative_link_of_the_page_resolves(page: Path) -> None:
    missing = []
    for target in _relative_targets(page):
        path = unquote(target.split("#", 1)[0])
        if not (page.parent / path).exists():
            missing.append(target)
    assert not missing, f"{page.relative_to(REPO)}: links to missing files: {missing}"


def test_the_link_pattern_finds_links_and_skips_code_and_urls(tmp_path: Path) -> None:
    page = tmp_path / "p.md"
    page.write_text("[a](x.md) ![b](img/y.png \"t\") [c](https://e.org) [d](#top) `[e](z.md)`\n"
                    "```\n[f](w.md)\n```\n", encoding="utf-8")
    assert _relative_targets(page) == ["x.md", "img/y.png"]
