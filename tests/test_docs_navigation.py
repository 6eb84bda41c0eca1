"""The site's sidebar navigation, resolved once per folder (``docs/_ext/shared_navigation.py``):
marking a page's entry as Sphinx marks it, on hand-built toctrees, and a small Furo site built
with and without the extension giving the same pages byte for byte (skipped without the
``docs`` extra)."""

from __future__ import annotations

import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "docs" / "_ext"))

import shared_navigation as nav  # noqa: E402

#: A toctree as Sphinx resolves it for a page in no toctree: two top-level entries, the second
#: with two children, one of which (``b.html``) is also listed at the top with an anchor.
UNMARKED = (
    '<p class="caption" role="heading"><span class="caption-text">Guide</span></p>\n'
    '<ul>\n'
    '<li class="toctree-l1"><a class="reference internal" href="a.html">A</a></li>\n'
    '<li class="toctree-l1"><a class="reference internal" href="b.html#part">B, a part</a></li>\n'
    '<li class="toctree-l1"><a class="reference internal" href="api.html">API</a><ul>\n'
    '<li class="toctree-l2"><a class="reference internal" href="b.html">B</a></li>\n'
    '<li class="toctree-l2"><a class="reference internal" href="c.html">C</a></li>\n'
    '</ul>\n'
    '</li>\n'
    '</ul>\n'
)


def test_a_nested_page_marks_its_link_and_every_list_and_item_above_it():
    got = nav.mark_current(UNMARKED, "b.html")
    expected = (
        UNMARKED.replace("<ul>\n<li", '<ul class="current">\n<li', 1)
        .replace('toctree-l1"><a class="reference internal" href="api.html">API</a><ul>',
                 'toctree-l1 current"><a class="reference internal" href="api.html">API</a>'
                 '<ul class="current">')
        .replace('<li class="toctree-l2"><a class="reference internal" href="b.html">',
                 '<li class="toctree-l2 current"><a class="current reference internal" href="#">')
    )  # fmt: skip
    assert got == expected
    assert 'href="b.html#part"' in got  # a link to a part of the page is not its entry


def test_a_top_level_page_a_page_listed_twice_and_a_page_listed_nowhere():
    top = nav.mark_current(UNMARKED, "a.html")
    assert top.count("current") == 3  # its link, its item, the top list
    assert '<li class="toctree-l1 current"><a class="current reference internal" href="#">A' in top
    twice = UNMARKED.replace('href="c.html">C', 'href="a.html">A again')
    marked = nav.mark_current(twice, "a.html")
    assert marked.count('href="#"') == 2
    assert marked.count('<ul class="current">') == 2  # the top list once, the nested one once
    assert '<li class="toctree-l1 current"><a class="reference internal" href="api.html">' in marked
    assert nav.mark_current(UNMARKED, "elsewhere.html") == UNMARKED


def test_html_that_is_not_a_toctree_is_refused():
    with pytest.raises(ValueError, match="</li> at 0 closes nothing"):
        nav.mark_current("</li><ul></ul>", "a.html")


def _site(root: Path, extension: bool, extra: bool = False) -> Path:
    """A small Furo site: pages in the root and in a folder, one listed twice, one listed in
    no toctree (and with ``extra`` one more page, ``e``, in the first toctree); built (not in
    parallel) into ``root/out``."""
    from sphinx.cmd.build import build_main

    src = root / "src"
    (src / "sub").mkdir(parents=True)
    extensions = ["shared_navigation"] if extension else []
    (src / "conf.py").write_text(
        f"import sys\nsys.path.insert(0, {str(ROOT / 'docs' / '_ext')!r})\n"
        f"project = 'site'\nhtml_theme = 'furo'\nextensions = {extensions!r}\n"
    )
    pages = {
        "index": (".. toctree::\n   :caption: Guide\n\n   a\n   sub/b\n   sub/c\n"
                  + ("   e\n" if extra else "")
                  + "\n.. toctree::\n   :caption: Again\n\n   a\n"),
        "a": "",
        "sub/b": ".. toctree::\n\n   d\n",
        "sub/c": "",
        "sub/d": "",
        "sub/alone": ":orphan:\n\n",
        **({"e": ""} if extra else {}),
    }
    for name, body in pages.items():
        title = name.rpartition("/")[2].title()
        (src / f"{name}.rst").write_text(f"{body}\n{title}\n{'=' * len(title)}\n\nText.\n")
    out = root / "out"
    assert build_main(["-q", "-W", "-b", "html", str(src), str(out)]) == 0
    return out


def test_a_site_built_with_the_extension_is_the_site_built_without_it(tmp_path, monkeypatch):
    pytest.importorskip("sphinx")
    furo = pytest.importorskip("furo")
    if not hasattr(furo, "_compute_navigation_tree"):
        pytest.skip("this Furo builds its navigation otherwise; the extension does nothing")
    # the extension replaces Furo's function for the process; put Furo's back afterwards
    monkeypatch.setattr(furo, "_compute_navigation_tree", furo._compute_navigation_tree)
    plain = _site(tmp_path / "plain", extension=False)
    shared = _site(tmp_path / "shared", extension=True)
    # a second build in the same process (of a site with one more page) starts from Furo's
    # function, not from the first build's, whose toctree lacks that page
    again = _site(tmp_path / "again", extension=True, extra=True)
    assert 'href="e.html"' in (again / "a.html").read_text()
    assert 'class="current reference internal" href="#">E<' in (again / "e.html").read_text()
    pages = sorted(p.relative_to(plain) for p in plain.rglob("*.html"))
    wanted = {Path("a.html"), Path("sub/b.html"), Path("sub/d.html"), Path("sub/alone.html")}
    assert wanted <= set(pages)
    for page in pages:
        assert (shared / page).read_bytes() == (plain / page).read_bytes(), page
    assert 'class="current reference internal" href="#"' in (plain / "sub" / "d.html").read_text()
