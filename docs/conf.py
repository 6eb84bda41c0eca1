"""Sphinx configuration of the lantern_jax documentation.

Build it from the project root (``pip install -e ".[docs]"`` first)::

    sphinx-build -W --keep-going -b html docs docs/_build/html -D nb_execution_mode=off

The notebooks (``notebooks/*.py``, jupytext percent format) are copied into ``docs/notebooks/``
at the start of a build and executed by MyST-NB in their small setting
(``LANTERN_NOTEBOOK_SMALL=1`` unless the environment says otherwise) when the ``-D
nb_execution_mode=off`` option is left out; with it the pages are built without running them.
"""

from __future__ import annotations

import os
import re
import shutil
import sys
from pathlib import Path

DOCS = Path(__file__).resolve().parent
ROOT = DOCS.parent
sys.path.insert(0, str(ROOT))  # autodoc reads the package of this checkout
sys.path.insert(0, str(DOCS / "_ext"))  # this site's own extensions

# The notebooks run in their small, fast setting unless asked otherwise; the kernels that
# MyST-NB starts inherit this process's environment.
os.environ.setdefault("LANTERN_NOTEBOOK_SMALL", "1")
os.environ.setdefault("MPLBACKEND", "Agg")  # autodoc imports viz modules; no display here

# The notebooks live in notebooks/ (run by tests/test_notebook.py too); the site renders a
# fresh copy of them (docs/notebooks/ is generated and git-ignored).
_NB_SRC, _NB_DST = ROOT / "notebooks", DOCS / "notebooks"
_NB_DST.mkdir(exist_ok=True)
for _old in _NB_DST.glob("*.py"):
    if not (_NB_SRC / _old.name).exists():
        _old.unlink()
for _nb in sorted(_NB_SRC.glob("*.py")):
    _dst = _NB_DST / _nb.name
    if not _dst.exists() or _dst.read_bytes() != _nb.read_bytes():
        shutil.copyfile(_nb, _dst)

project = "lantern_jax"
author = "the lantern_jax authors"
copyright = "the lantern_jax authors"  # noqa: A001

extensions = [
    "myst_nb",
    "sphinx.ext.autodoc",
    "sphinx.ext.autosummary",
    "sphinx.ext.napoleon",
    "sphinx.ext.viewcode",
    "shared_navigation",  # docs/_ext/shared_navigation.py
]

# Markdown pages, the API pages autosummary writes, and the notebooks.  Only these: the
# one-off scripts of investigations/ are not notebooks.
# (.rst first: autosummary writes its pages with the first suffix)
source_suffix = {".rst": "restructuredtext", ".md": "myst-nb", ".py": "myst-nb"}
include_patterns = ["**.md", "**.rst", "notebooks/*.py"]
exclude_patterns = ["_build", "**/.ipynb_checkpoints", "conf.py"]
templates_path = ["_templates"]

# MyST
myst_enable_extensions = ["colon_fence", "deflist", "dollarmath"]
myst_heading_anchors = 3

# MyST-NB: jupytext percent scripts are notebooks; run them on every build.
nb_custom_formats = {".py": ["jupytext.reads", {"fmt": "py:percent"}]}
nb_execution_mode = "force"
nb_execution_timeout = 1800
nb_execution_raise_on_error = True
nb_execution_show_tb = True
nb_execution_in_temp = True  # a notebook's files land in a temporary folder
nb_merge_streams = True

# API reference: every module of the package, found recursively (docs/api.md).
autosummary_generate = True
autosummary_imported_members = False
autodoc_default_options = {
    "members": True,
    "show-inheritance": True,
    "ignore-module-all": True,  # lantern_jax/__init__.py re-exports; document each name once
}
autodoc_member_order = "bysource"
autodoc_typehints = "description"
autodoc_preserve_defaults = True
napoleon_google_docstring = True
napoleon_numpy_docstring = False
napoleon_use_rtype = False

html_theme = "furo"
html_title = "lantern_jax"
html_static_path: list[str] = []


# Many docstrings name each returned value as they name the arguments ("Returns:" then
# "name: shape, unit, meaning" per value); Napoleon reads a Returns section as one value.  Such
# a section becomes a list of the named values before Napoleon sees the docstring; an unnamed
# one ("Returns:" then a description) is left to Napoleon.
_SECTION = re.compile(r"^(\s*)(Returns|Yields):\s*$")
_NAMED = re.compile(r"^([A-Za-z_]\w*(?:, [A-Za-z_]\w*)*)( \([^)]*\))?: (.+)$")


def _indent(line: str) -> int:
    return len(line) - len(line.lstrip())


def _named_returns(app, what, name, obj, options, lines: list[str]) -> None:
    i = 0
    while i < len(lines):
        m = _SECTION.match(lines[i])
        if not m:
            i += 1
            continue
        indent, j = len(m.group(1)), i + 1
        while j < len(lines) and (not lines[j].strip() or _indent(lines[j]) > indent):
            j += 1
        while j > i + 1 and not lines[j - 1].strip():
            j -= 1
        body = lines[i + 1 : j]
        items = [line for line in body if line.strip()]
        if not items:
            i = j
            continue
        at = min(_indent(line) for line in items)
        if not all(_NAMED.match(line.strip()) for line in items if _indent(line) == at):
            i = j
            continue
        out = [" " * indent + f":{m.group(2)}:"]
        for line in body:
            if not line.strip():
                out.append("")
            elif _indent(line) == at:
                head = _NAMED.match(line.strip())
                out.append(
                    " " * (indent + 4) + f"* **{head.group(1)}**{head.group(2) or ''}"
                    f" -- {head.group(3)}"
                )
            else:
                out.append(" " * (indent + 6) + line.strip())
        lines[i:j] = out
        i += len(out)


def setup(app):
    app.connect("autodoc-process-docstring", _named_returns, priority=400)  # before Napoleon
