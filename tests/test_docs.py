"""The documentation holds together: every relative link resolves, every page under docs/ is reachable
from the README by links, and the design doc cites no commit (history lives in docs/studies/ and git)."""
from __future__ import annotations

import re
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
LINK = re.compile(r"\]\(([^)#\s]+)(?:#[^)]*)?\)")


def _links(page: Path) -> list[Path]:
    out = []
    for target in LINK.findall(page.read_text(encoding="utf-8")):
        if target.startswith(("http:", "https:", "mailto:")):
            continue
        out.append((page.parent / target).resolve())
    return out


def _pages() -> list[Path]:
    return [REPO / "README.md"] + sorted((REPO / "docs").rglob("*.md"))


def test_relative_links_resolve():
    broken = [f"{p.relative_to(REPO)} -> {t}" for p in _pages() for t in _links(p) if not t.exists()]
    assert not broken, "broken links:\n" + "\n".join(broken)


def test_every_doc_is_reachable_from_the_readme():
    seen, todo = set(), [REPO / "README.md"]
    while todo:
        page = todo.pop()
        if page in seen:
            continue
        seen.add(page)
        for t in _links(page):
            if t.is_dir():
                todo.extend(sorted(t.glob("*.md")))
            elif t.suffix == ".md" and t.exists():
                todo.append(t)
    orphans = [str(p.relative_to(REPO)) for p in _pages() if p.resolve() not in seen]
    assert not orphans, f"not linked from the README or a page it links: {orphans}"


def test_design_doc_cites_no_commit():
    text = (REPO / "docs" / "method.md").read_text(encoding="utf-8")
    hashes = [h for h in re.findall(r"\b[0-9a-f]{7,40}\b", text) if re.search(r"[a-f]", h) and re.search(r"\d", h)]
    assert not hashes, f"commit ids in docs/method.md: {hashes}"
