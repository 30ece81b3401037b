"""The README is a user's guide that links into docs/: every relative link of README.md and docs/*.md resolves
(the file, and the heading a ``#fragment`` names), and the README stays short."""

from __future__ import annotations

import re
from pathlib import Path

import pytest

from conftest import REPO

REPO = Path(REPO)
PAGES = [REPO / "README.md", *sorted((REPO / "docs").glob("*.md"))]
LINK = re.compile(r"\[[^\]]*\]\(([^)\s]+)\)")


def anchors(page: Path) -> set[str]:
    """GitHub's heading anchors: lower case, punctuation dropped, spaces as hyphens."""
    out = set()
    for line in page.read_text().splitlines():
        if m := re.match(r"^#+\s+(.*)", line):
            out.add(re.sub(r"[^\w\- ]", "", m.group(1).strip().lower()).replace(" ", "-"))
    return out


def links(page: Path) -> list[str]:
    text = re.sub(r"```.*?```", "", page.read_text(), flags=re.S)  # not inside code blocks
    return [target for target in LINK.findall(text) if not re.match(r"^[a-z]+:", target)]


@pytest.mark.parametrize("page", PAGES, ids=lambda p: p.relative_to(REPO).as_posix())
def test_every_relative_link_resolves(page):
    for target in links(page):
        path, _, fragment = target.partition("#")
        dest = (page.parent / path).resolve() if path else page
        assert dest.exists(), f"{page.name}: {target} points to nothing"
        if fragment and dest.suffix == ".md":
            assert fragment in anchors(dest), f"{page.name}: {target}: no such heading in {dest.name}"


def test_the_readme_is_a_guide_that_links_every_docs_page():
    readme = (REPO / "README.md").read_text()
    assert len(readme.splitlines()) <= 150
    hashes = re.findall(r"\b(?=[0-9a-f]*[a-f])(?=[0-9a-f]*[0-9])[0-9a-f]{7,40}\b", readme)
    assert not hashes, f"commit hashes in the README (history belongs in docs/): {hashes}"
    linked = {(REPO / t.partition("#")[0]).resolve() for t in links(REPO / "README.md") if t.startswith("docs/")}
    assert linked == {p.resolve() for p in PAGES[1:]}, "a docs page the README does not link"
    assert readme.index("make pipeline") < readme.index("## What it is")  # the two commands come first


def test_the_link_check_can_fail(tmp_path):
    page = tmp_path / "page.md"
    page.write_text("# Title\n[ok](page.md#title) [missing](nowhere.md) [anchor](page.md#nope)\n")
    assert links(page) == ["page.md#title", "nowhere.md", "page.md#nope"]
    assert "title" in anchors(page) and "nope" not in anchors(page)
    assert not (page.parent / "nowhere.md").exists()
    with pytest.raises(AssertionError, match="points to nothing"):  # the check itself, on a page with a bad link
        test_every_relative_link_resolves(page)
    page.write_text("# Title\n[anchor](page.md#nope)\n")
    with pytest.raises(AssertionError, match="no such heading"):
        test_every_relative_link_resolves(page)


def test_the_datasets_page_lists_every_feature_a_dataset_can_have():
    from hnsdt.data.features import FEATURES

    table = "\n".join(line for line in (REPO / "docs/datasets.md").read_text().splitlines() if line.startswith("| `"))
    assert [f.name for f in FEATURES if f"`{f.name}`" not in table] == []
