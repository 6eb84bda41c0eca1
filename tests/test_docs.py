"""The README's and the documentation pages' code runs.

* Every fenced ``python`` block of ``README.md`` and ``docs/*.md`` compiles, and (marked slow:
  the blocks evaluate small suites, which compiles simulator programs) runs: the blocks of one
  page in order, in one namespace, in an empty working folder.
* Every ``lantern-jax`` command shown in a shell block parses with the command line's own parser.

A block that must not run (a training run of many minutes, a sketch with ``...``) is preceded by
the line ``<!-- docs-test: skip (why) -->``; the reason is required and such blocks stay few.
"""

from __future__ import annotations

import io
import re
import shlex
from contextlib import redirect_stderr, redirect_stdout
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
#: The README and the documentation's own pages (not the folders beside them, such as
#: docs/investigations/, which hold one-off scripts of their own).
PAGES = [ROOT / "README.md", *sorted((ROOT / "docs").glob("*.md"))]
SKIP = re.compile(r"^<!--\s*docs-test:\s*skip\s*\((?P<why>[^)]+)\)\s*-->\s*$")
FENCE = re.compile(r"^(?P<fence>```+|~~~+)\s*(?P<info>[^`\s]*)")
PYTHON = {"python", "py", "python3"}
SHELL = {"bash", "sh", "shell", "console"}
#: Most blocks run; at most this many may be skipped, each with its reason.
MAX_SKIPPED = 3
#: Extras a block may need; without them installed the block is skipped, not failed.
OPTIONAL_MODULES = {"brax", "onnx", "onnxruntime"}


def _rel(path: Path) -> str:
    return str(path.relative_to(ROOT))


def blocks(path: Path) -> list[dict]:
    """Fenced code blocks of a Markdown file: language, code, first line, skip reason."""
    out, lines = [], path.read_text(encoding="utf-8").splitlines()
    i = 0
    while i < len(lines):
        m = FENCE.match(lines[i])
        if not m:
            i += 1
            continue
        fence, info = m.group("fence"), m.group("info").strip("{}").lower()
        skip = SKIP.match(lines[i - 1]) if i else None
        body, j = [], i + 1
        while j < len(lines) and not lines[j].startswith(fence):
            body.append(lines[j])
            j += 1
        out.append(
            dict(lang=info, code="\n".join(body) + "\n", line=i + 1,
                 skip=skip.group("why").strip() if skip else None)
        )  # fmt: skip
        i = j + 1
    return out


def _python_blocks(path: Path) -> list[dict]:
    return [b for b in blocks(path) if b["lang"] in PYTHON]


PY_PAGES = [p for p in PAGES if _python_blocks(p)]


def test_the_pages_hold_code_blocks():
    assert ROOT / "README.md" in PY_PAGES
    assert len(PY_PAGES) >= 5, [_rel(p) for p in PY_PAGES]


def test_every_python_block_compiles():
    compiled = 0
    for page in PY_PAGES:
        for b in _python_blocks(page):
            if b["skip"] is None:
                code = compile(b["code"], f"{_rel(page)}:{b['line']}", "exec")
                assert code.co_filename.endswith(f":{b['line']}")
                compiled += 1
    assert compiled >= 10, f"only {compiled} Python blocks found in the pages"


def test_skipped_blocks_are_few_and_say_why():
    skipped = [(_rel(p), b["line"], b["skip"]) for p in PAGES for b in blocks(p) if b["skip"]]
    assert len(skipped) <= MAX_SKIPPED, skipped
    assert all(len(why) >= 10 for _, _, why in skipped), skipped


def test_readme_is_short():
    assert len((ROOT / "README.md").read_text(encoding="utf-8").splitlines()) <= 200


def shell_commands(path: Path) -> list[tuple[int, list[str]]]:
    """``lantern-jax`` command lines of a page's shell blocks, as argument lists (comments,
    line continuations, environment assignments and a ``.venv/bin/`` prefix handled)."""
    found = []
    for b in blocks(path):
        if b["lang"] not in SHELL or b["skip"]:
            continue
        text = b["code"].replace("\\\n", " ")
        for k, line in enumerate(text.splitlines()):
            for part in re.split(r"&&|\|\||;|\|", line):
                words = shlex.split(part, comments=True)
                while words and re.match(r"^[A-Za-z_][A-Za-z0-9_]*=", words[0]):
                    words = words[1:]  # VAR=value before the command
                if words and words[0].rsplit("/", 1)[-1] == "lantern-jax":
                    found.append((b["line"] + k, words[1:]))
    return found


COMMANDS = [(p, line, argv) for p in PAGES for line, argv in shell_commands(p)]

#: Commands of the project's environment that a page's shell blocks run: written one way only,
#: from the project's virtual environment (``.venv/bin/NAME``), as the README's first commands.
VENV_COMMANDS = ("lantern-jax", "python", "pip", "sphinx-build", "pytest")


def test_every_page_writes_commands_one_way():
    """Every command of the environment in a shell block is ``.venv/bin/NAME`` (never a bare
    ``lantern-jax`` or ``python`` that only works in an activated environment)."""
    bare = []
    for p in PAGES:
        for b in blocks(p):
            if b["lang"] not in SHELL or b["skip"]:
                continue
            for k, line in enumerate(b["code"].replace("\\\n", " ").splitlines()):
                for part in re.split(r"&&|\|\||;|\|", line):
                    words = shlex.split(part, comments=True)
                    while words and re.match(r"^[A-Za-z_][A-Za-z0-9_]*=", words[0]):
                        words = words[1:]
                    if words and words[0] in VENV_COMMANDS:
                        bare.append(f"{_rel(p)}:{b['line'] + k}: {words[0]}")
    assert not bare, f"write .venv/bin/NAME: {bare}"


def test_the_pages_show_commands():
    assert len(COMMANDS) >= 30
    assert any(argv == ["evaluate"] for _, _, argv in COMMANDS)


@pytest.mark.parametrize(
    ("argv",), [pytest.param(argv, id=f"{_rel(p)}:{line}") for p, line, argv in COMMANDS]
)
def test_every_command_parses(argv):
    from lantern_jax.cli import build_parser

    parser = build_parser()
    err = io.StringIO()
    try:
        with redirect_stderr(err):
            args = parser.parse_args(argv)
    except SystemExit as e:  # argparse's usage error
        pytest.fail(f"lantern-jax {shlex.join(argv)}: exit {e.code}: {err.getvalue().strip()}")
    assert args is not None


def _page_param(page: Path):
    """The README's blocks run with the slow tests; a documentation page's are ``docs_pages``
    as well (minutes each, run on demand: ``python -m pytest -q -m docs_pages``)."""
    marks = () if page.name == "README.md" else (pytest.mark.docs_pages,)
    return pytest.param(page, id=_rel(page), marks=marks)


@pytest.mark.slow
@pytest.mark.parametrize("page", [_page_param(p) for p in PY_PAGES])
def test_python_blocks_run(page, tmp_path, monkeypatch):
    """A page's Python blocks, in order, in one namespace, in an empty working folder."""
    monkeypatch.chdir(tmp_path)
    namespace: dict = {"__name__": "__docs__"}
    runnable = [b for b in _python_blocks(page) if not b["skip"]]
    if not runnable:
        pytest.skip(f"{_rel(page)}: every Python block is marked to skip (see the marker's reason)")
    for b in runnable:
        where = f"{_rel(page)}:{b['line']}"
        try:
            with redirect_stdout(io.StringIO()):
                exec(compile(b["code"], where, "exec"), namespace)  # noqa: S102
        except ModuleNotFoundError as e:
            if e.name and e.name.split(".")[0] in OPTIONAL_MODULES:
                pytest.skip(f"{where} needs the optional {e.name!r}")
            raise
    defined = set(namespace) - {"__name__", "__builtins__"}
    assert defined, f"{_rel(page)}: its blocks ran but defined nothing"


def test_the_stress_page_shows_the_recorded_cells():
    """The stress page's table of every cell is what ``benchmarks/stress_cells.py`` prints
    from the recorded comparison files today."""
    import importlib.util

    spec = importlib.util.spec_from_file_location(
        "stress_cells", ROOT / "benchmarks" / "stress_cells.py"
    )
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    results = ROOT / "benchmarks" / "results"
    folders = [results / f"stress_adversary_{n}" for n in ("cpu", "learned", "hybrid")]
    table = module.markdown(*module.load(folders))
    assert table.count("\n") > 40  # a row per policy, family and method
    assert table in (ROOT / "docs" / "stress.md").read_text()


def test_the_stress_page_shows_every_method_at_the_largest_dimension():
    """The stress page's table of every method at the largest dimension (256 rollouts per
    restart) is what ``benchmarks/plot_stress_dims.py`` computes from the recorded folders, and
    the page shows its figure."""
    import importlib.util

    spec = importlib.util.spec_from_file_location(
        "plot_stress_dims", ROOT / "benchmarks" / "plot_stress_dims.py"
    )
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    page = (ROOT / "docs" / "stress.md").read_text()
    assert "](_static/stress_dims.png)" in page
    assert (ROOT / "docs" / "_static" / "stress_dims.png").is_file()
    for cell, folders in module.DOCUMENTED.items():
        policy, family = cell.split()
        rows = [line for line in page.splitlines()
                if line.startswith(f"| `{policy}` {family} ") and "/16, " in line]  # fmt: skip
        assert len(rows) == 1, cell
        got = module.largest(module.load([module.RESULTS / f for f in folders]))
        assert set(got) == {"gradient", "hybrid", "random", "cmaes"}, cell
        for method, text in got.items():
            assert text in rows[0], (cell, method, text)
