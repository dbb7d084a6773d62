"""The documentation's house rules: no page under docs/ over about 400 lines (guide text on
the page, measured logs on its validation page), every relative link of the docs and the
README reaches a file and, with an anchor, a heading of that file, and every page is
listed in docs/architecture.md's map of the docs."""

import re
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
DOCS = ROOT / "docs"

#: the longest a docs page may be, in lines
PAGE_LINES = 400

#: a Markdown link or image: [text](target) (inline code spans are dropped before matching)
LINK = re.compile(r"!?\[[^\]]*\]\(([^)\s]+)\)")
CODE_SPAN = re.compile(r"`[^`\n]*`")
FENCE = re.compile(r"^```.*?^```", re.S | re.M)


def _pages():
    return sorted(DOCS.glob("*.md"))


def _slug(heading: str) -> str:
    """GitHub's anchor of a heading: lower case, inline code marks and punctuation other
    than '-' and '_' dropped, spaces to '-'."""
    text = heading.strip().lower().replace("`", "")
    return re.sub(r"[^\w\- ]", "", text).replace(" ", "-")


def _anchors(path: Path) -> set[str]:
    seen: dict[str, int] = {}
    out = set()
    for line in FENCE.sub("", path.read_text()).splitlines():
        if m := re.match(r"#{1,6}\s+(.*)", line):
            s = _slug(m.group(1))
            n = seen.get(s, 0)
            seen[s] = n + 1
            out.add(s if n == 0 else f"{s}-{n}")
    return out


def _links(path: Path):
    """(line number, target) of every relative link outside code blocks and code spans."""
    text = path.read_text()
    for i, line in enumerate(FENCE.sub(lambda m: "\n" * m.group(0).count("\n"), text).splitlines(), 1):
        for target in LINK.findall(CODE_SPAN.sub("", line)):
            if not re.match(r"[a-z]+:", target):
                yield i, target


def _broken(path: Path, root: Path = ROOT) -> list[str]:
    bad = []
    for i, target in _links(path):
        file, _, anchor = target.partition("#")
        dest = (path.parent / file).resolve() if file else path
        where = f"{path.relative_to(root)}:{i}: {target}"
        if not dest.exists():
            bad.append(f"{where} (no such file)")
        elif anchor and dest.suffix == ".md" and anchor not in _anchors(dest):
            bad.append(f"{where} (no heading with that anchor)")
    return bad


def test_no_docs_page_over_400_lines():
    long = [f"{p.name}: {n}" for p in _pages() if (n := len(p.read_text().splitlines())) > PAGE_LINES]
    assert not long, f"split these pages (guide / validation), at most {PAGE_LINES} lines:\n" + "\n".join(long)


def test_every_relative_link_reaches_its_file_and_heading():
    bad = [b for p in [ROOT / "README.md", *_pages()] for b in _broken(p)]
    assert not bad, "broken links:\n" + "\n".join(bad)


def test_every_docs_page_is_in_the_architecture_map():
    arch = DOCS / "architecture.md"
    listed = {Path(t.partition("#")[0]).name for _, t in _links(arch)}
    missing = [p.name for p in _pages() if p != arch and p.name not in listed]
    assert not missing, f"docs/architecture.md's map of the docs lacks {missing}"


def test_the_link_check_finds_a_missing_file_and_a_missing_heading(tmp_path):
    """The checker itself: a good link passes, a missing file and a missing anchor fail,
    a link inside code is not a link, and headings with code and punctuation slug as on GitHub."""
    (tmp_path / "a.md").write_text("# A page\n\n## `--max-scale` in rounds (issue #16)\n\n## A page\n")
    (tmp_path / "b.md").write_text(
        "[ok](a.md#--max-scale-in-rounds-issue-16) [ok2](a.md#a-page-1) [self](#b)\n"
        "[gone](c.md) [no anchor](a.md#nowhere) `[code](x.md)`\n\n# B\n```\n[fenced](y.md)\n```\n"
    )
    problems = [b.split(": ", 1)[1] for b in _broken(tmp_path / "b.md", tmp_path)]
    assert problems == ["c.md (no such file)", "a.md#nowhere (no heading with that anchor)"]
