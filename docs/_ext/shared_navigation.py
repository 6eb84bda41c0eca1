"""Furo's sidebar navigation, resolved once per folder instead of once per page.

Furo writes the whole site's navigation into every page it renders, resolving Sphinx's global
toctree for that page: 40 of an unexecuted build's 88 s of CPU time on a 2-core CPU, for about
420 pages (most of them API pages).  What differs between two pages of one folder is only which
entry is marked current, since every link is relative to the folder.  So the toctree is
resolved once per folder, for a page name that is in no toctree (:data:`UNLISTED_PAGE`), and
each page marks its own entry in a copy (:func:`mark_current`).  Furo then adds its
checkboxes to that tree, as it does to its own.  A page in no toctree (the highlighted source of
every module, the indices) marks none, so its whole navigation, checkboxes added, is the same
for its folder and is made once.  The navigation written is the one Furo writes, byte for
byte: checked on every page of this site's build, and by ``tests/test_docs_navigation.py`` on a
small site built both ways.

Sphinx loads this file as an extension (``docs/conf.py``); with another Furo, one without the
function replaced here, every page resolves its own, as Furo does.
"""

from __future__ import annotations

import re

#: A page name in no toctree, one per folder: the global toctree resolved for it has every link
#: relative to that folder and no entry marked current.
UNLISTED_PAGE = "__navigation__"

#: The tags that decide which entries are current: list items, lists and links.  Sphinx's
#: toctree HTML double-quotes every attribute and nests no other ``li`` or ``ul``.
_TOCTREE_TAG = re.compile(r"<(/?)(li|ul|a)\b([^>]*)>")
_HREF = re.compile(r'\bhref="([^"]*)"')
_CLASS = re.compile(r'\bclass="([^"]*)"')


def _with_class(tag: str, name: str, first: bool = False) -> str:
    """An opening tag's text with ``name`` in its class attribute (added last, or first;
    unchanged when it is there already)."""
    found = _CLASS.search(tag)
    if found is None:
        return tag[:-1] + f' class="{name}">'
    classes = found.group(1).split()
    if name in classes:
        return tag
    classes = [name, *classes] if first else [*classes, name]
    return tag[: found.start()] + f'class="{" ".join(classes)}"' + tag[found.end() :]


def mark_current(html: str, href: str) -> str:
    """The resolved toctree ``html`` as Sphinx resolves it for the page that its entries link
    to with ``href``.

    As ``sphinx.environment.adapters.toctree._toctree_add_classes`` does: the entry's link
    points to ``#`` and has the class ``current`` (first, where Sphinx's HTML writer puts it),
    and every ``li`` and ``ul`` above it has ``current`` (last).  A link with an anchor
    (``page.html#part``) is not the page's own entry; a page listed twice marks both entries
    and an element above both once; a page listed nowhere leaves ``html`` as it is.  One pass
    over the tags, keeping the ``li`` and ``ul`` that are open.

    Args:
        html: a toctree resolved for a page in no toctree (nothing marked current).
        href: the page's link as it appears in ``html``, e.g. ``stress.html``.

    Returns:
        The marked HTML.

    Raises:
        ValueError: a closing ``li`` or ``ul`` with nothing open (not a toctree's HTML).
    """
    open_tags: list[re.Match] = []
    edits: dict[tuple[int, int], str] = {}
    for tag in _TOCTREE_TAG.finditer(html):
        closing, name, attributes = tag.groups()
        if name != "a":
            if not closing:
                open_tags.append(tag)
            elif not open_tags:
                raise ValueError(f"mark_current: </{name}> at {tag.start()} closes nothing")
            else:
                open_tags.pop()
            continue
        link = _HREF.search(attributes)
        if closing or link is None or link.group(1) != href:
            continue
        text = tag.group(0).replace(f'href="{href}"', 'href="#"', 1)
        edits[tag.span()] = _with_class(text, "current", first=True)
        for above in open_tags:
            edits.setdefault(above.span(), _with_class(above.group(0), "current"))
    out, end = [], 0
    for (start, stop), text in sorted(edits.items()):
        out += [html[end:start], text]
        end = stop
    return "".join(out) + html[end:]


def share_navigation(app) -> None:
    """Replace Furo's navigation builder by one that resolves the toctree once per folder
    (``builder-inited``)."""
    import furo

    compute = getattr(furo, "_compute_navigation_tree", None)
    if compute is None:
        return
    # a build before this one in the same process replaced Furo's function with one bound to
    # its own application: start from Furo's again
    compute = getattr(compute, "furo_navigation", compute)
    resolved: dict[tuple, str] = {}  # (folder, toctree options) -> the unmarked toctree
    unmarked: dict[str, str] = {}  # folder -> the navigation of its pages in no toctree

    def navigation(context: dict) -> str:
        if "toctree" not in context:
            return compute(context)
        page = context.get("pagename", "")
        folder = page.rpartition("/")[0]
        listed = page in app.env.all_docs
        if not listed and folder in unmarked:
            return unmarked[folder]
        unlisted = f"{folder}/{UNLISTED_PAGE}" if folder else UNLISTED_PAGE

        def toctree(**kwargs) -> str:
            key = (folder, tuple(sorted(kwargs.items())))
            if key not in resolved:
                resolved[key] = app.builder._get_local_toctree(unlisted, **kwargs)
            if not listed:
                return resolved[key]
            return mark_current(resolved[key], app.builder.get_relative_uri(unlisted, page))

        html = compute({**context, "toctree": toctree})
        if not listed:
            unmarked[folder] = html
        return html

    navigation.furo_navigation = compute
    furo._compute_navigation_tree = navigation


def setup(app) -> dict:
    """Sphinx's entry point for this extension."""
    app.connect("builder-inited", share_navigation)
    return {"parallel_read_safe": True, "parallel_write_safe": True}
