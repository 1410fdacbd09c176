"""The docs follow the code: every algorithm has its page with the parameter tables generated from
its declarations, in sync; the README stays a short front page whose links resolve."""

from __future__ import annotations

import re
from pathlib import Path

from toolbox import docs
from toolbox.registry import registry

ROOT = Path(__file__).resolve().parents[1]
PAGES = sorted((ROOT / "docs").glob("*.md"))


def test_every_built_in_algorithm_has_its_tables_on_its_plugins_page():
    algorithms = {a.id: a for a in registry().algorithms.values() if a.distribution == "lidar-toolbox"}
    for aid, alg in algorithms.items():
        page = ROOT / "docs" / f"{alg.plugin}.md"
        assert page.exists(), f"{alg.plugin} has no docs page ({page.name})"
        assert aid in docs.documented(page.read_text()), f"docs/{page.name} has no help block for {aid}"


def test_the_pages_tables_are_in_sync_with_the_declarations():
    assert docs.main(["--check", *map(str, PAGES)]) == 0


def test_a_changed_declaration_makes_its_page_stale():
    alg = registry().get("tophat")
    text = f"<!-- help:tophat -->\n{docs.markdown(alg)}<!-- /help:tophat -->"
    assert docs.sync(text, {"tophat": alg}) == text
    stale = text.replace("cell of the binary mask", "cell of the mask")
    assert docs.sync(stale, {"tophat": alg}) == text
    assert "| `cell_size_m` | float | 0.5 | m | [0.01, 100] |" in text


def test_the_readme_is_short_and_its_links_resolve():
    readme = (ROOT / "README.md").read_text()
    assert readme.count("\n") <= 250
    for page in [ROOT / "README.md", *PAGES]:
        for target in re.findall(r"\]\(([^)#\s]+)(?:#[^)]*)?\)", page.read_text()):
            if not target.startswith(("http://", "https://")):
                assert (page.parent / target).exists(), f"{page.name} links to {target}, which is missing"
