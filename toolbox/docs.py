"""Reference tables of the algorithms for the docs pages, generated from their declarations.

``markdown(alg)`` is what ``toolbox help ALG --markdown`` prints: the inputs, outputs and
parameters as Markdown tables. A page under ``docs/`` holds it between the markers
``<!-- help:ALG -->`` and ``<!-- /help:ALG -->``; ``sync(page)`` rewrites those blocks from the
declarations and ``python -m toolbox.docs [--check] docs/*.md`` does so for pages (``--check``:
exit 1 naming the pages out of date, writing nothing). The tests run the check, so a parameter
changed in a plugin fails CI until its page is regenerated.
"""

from __future__ import annotations

import re
import sys
from pathlib import Path

BLOCK = re.compile(r"<!-- help:(?P<id>[\w-]+) -->\n.*?<!-- /help:(?P=id) -->", re.S)


def _cell(text) -> str:
    return str(text).replace("|", "\\|").replace("\n", " ")


def markdown(alg) -> str:
    """The inputs, outputs and parameters of ``alg`` (an Algorithm) as Markdown tables."""
    out = [f"*Generated from the declarations (`toolbox help {alg.id} --markdown`).*", "",
           "| input | kind | what |", "|---|---|---|"]
    for i in alg.inputs:
        kind = i.kind + (", one or more" if i.multiple else "") + (", optional" if i.optional else "")
        out.append(f"| `{i.name}` | {kind} | {_cell(i.description)} |")
    if not alg.inputs:
        out.append("| (none) | | |")
    out += ["", "| output | kind | what |", "|---|---|---|"]
    for o in alg.outputs:
        kind = f"{o.kind}, {o.extension}" + (", optional" if o.optional else "")
        out.append(f"| `{o.name}` | {kind} | {_cell(o.description)} |")
    out += ["", "| parameter | type | default | unit | allowed | what |", "|---|---|---|---|---|---|"]
    for p in alg.parameters:
        default = "auto" if p.default is None else p.default
        out.append(f"| `{p.name}` | {p.type.__name__} | {_cell(default)} | {p.unit or ''} | {_cell(p.allowed())} | "
                   f"{_cell(p.description)} |")
    return "\n".join(out) + "\n"


def sync(text: str, algorithms: dict) -> str:
    """``text`` (a docs page) with every help block regenerated; an unknown id is an error."""
    def block(m):
        aid = m.group("id")
        if aid not in algorithms:
            raise KeyError(f"the page names algorithm {aid!r}, which no installed plugin provides")
        return f"<!-- help:{aid} -->\n{markdown(algorithms[aid])}<!-- /help:{aid} -->"

    return BLOCK.sub(block, text)


def documented(text: str) -> set[str]:
    """The algorithm ids whose help block a page holds."""
    return {m.group("id") for m in BLOCK.finditer(text)}


def main(argv=None) -> int:
    from .registry import registry

    args = list(sys.argv[1:] if argv is None else argv)
    check = "--check" in args
    pages = [Path(a) for a in args if a != "--check"]
    algorithms = registry().algorithms
    stale = []
    for page in pages:
        text = page.read_text()
        new = sync(text, algorithms)
        if new != text:
            stale.append(str(page))
            if not check:
                page.write_text(new)
    if check and stale:
        print(f"out of date with the declarations: {', '.join(stale)}; run python -m toolbox.docs {' '.join(stale)}")
        return 1
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
