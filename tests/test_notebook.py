"""The notebooks run top to bottom in a fresh kernel.

Each is executed in its small configuration (``LANTERN_NOTEBOOK_SMALL=1``) with a kernel spec
that points at this interpreter, from an empty working directory.

Where ``LANTERN_EXECUTED_NOTEBOOKS`` names a folder of notebooks executed already — the
documentation build's ``docs/_build/jupyter_execute/notebooks`` (MyST-NB runs every notebook in
the same small setting; ``.ci/run`` builds the site before the slow tests) — a notebook found
there with the same code cells and outputs is checked from that run instead of being executed a
second time.
"""

from __future__ import annotations

import json
import os
import sys
from pathlib import Path

import pytest

jupytext = pytest.importorskip("jupytext")
nbclient = pytest.importorskip("nbclient")
pytest.importorskip("ipykernel")

NOTEBOOKS = Path(__file__).resolve().parents[1] / "notebooks"
KERNEL_NAME = "lantern"


def _install_kernelspec(root: Path) -> Path:
    """A kernel spec named :data:`KERNEL_NAME` that runs ipykernel with this interpreter."""
    share = root / "share" / "jupyter"
    kdir = share / "kernels" / KERNEL_NAME
    kdir.mkdir(parents=True)
    spec = {
        "argv": [sys.executable, "-m", "ipykernel_launcher", "-f", "{connection_file}"],
        "display_name": "lantern_jax (test)",
        "language": "python",
    }
    (kdir / "kernel.json").write_text(json.dumps(spec))
    return share


def _outputs(nb) -> list[dict]:
    return [out for cell in nb.cells if cell.cell_type == "code" for out in cell.get("outputs", [])]


def _text(out: dict) -> str:
    if out.get("output_type") == "stream":
        return out.get("text", "")
    return str(out.get("data", {}).get("text/plain", ""))


#: Folder of notebooks executed already (the documentation build's), if any.
EXECUTED_ENV = "LANTERN_EXECUTED_NOTEBOOKS"


def _code(nb) -> list[str]:
    return [c.source.strip() for c in nb.cells if c.cell_type == "code"]


def _executed(name: str) -> list[dict] | None:
    """The outputs of ``name`` from :data:`EXECUTED_ENV`'s folder, when it holds a run of the
    current code (same code cells) with outputs; else None."""
    folder = os.environ.get(EXECUTED_ENV)
    path = Path(folder or ".") / f"{Path(name).stem}.ipynb"
    if not folder or not path.is_file():
        return None
    import nbformat

    done = nbformat.read(path, as_version=4)
    if _code(done) != _code(jupytext.read(NOTEBOOKS / name)):
        return None
    outputs = _outputs(done)
    return outputs or None


def _run(name: str, tmp_path: Path, monkeypatch) -> list[dict]:
    """Execute ``notebooks/<name>`` in its small configuration (or take the outputs of a run of
    the same code, :func:`_executed`); returns every cell output."""
    done = _executed(name)
    if done is not None:
        return done
    share = _install_kernelspec(tmp_path / "kernel")
    monkeypatch.setenv("JUPYTER_PATH", str(share))
    monkeypatch.setenv("LANTERN_NOTEBOOK_SMALL", "1")
    monkeypatch.delenv("MPLBACKEND", raising=False)  # let ipykernel pick its inline backend
    workdir = tmp_path / "work"
    workdir.mkdir()
    nb = jupytext.read(NOTEBOOKS / name)
    client = nbclient.NotebookClient(
        nb,
        timeout=1200,
        kernel_name=KERNEL_NAME,
        resources={"metadata": {"path": str(workdir)}},
    )
    client.execute()
    return _outputs(nb)


def _clean_run(name: str, tmp_path: Path, monkeypatch) -> tuple[str, int]:
    """Run a notebook, fail on any error output; returns (all text output, PNG image count)."""
    outputs = _run(name, tmp_path, monkeypatch)
    errors = [o for o in outputs if o.get("output_type") == "error"]
    assert not errors, [f"{e.get('ename')}: {e.get('evalue')}" for e in errors]
    text = "\n".join(_text(o) for o in outputs)
    assert "TqdmWarning" not in text  # lantern_jax.core.progress: no widget, no warning
    images = [o for o in outputs if "image/png" in o.get("data", {})]
    return text, len(images)


def test_the_package_imports_in_a_kernel_without_a_warning(tmp_path, monkeypatch):
    """In a Jupyter kernel the package's progress bars come from ``tqdm.auto`` only where
    ``ipywidgets`` is installed: without it ``tqdm.auto`` warns on import ("IProgress not
    found"), which used to open every notebook's first output (``lantern_jax.core.progress``)."""
    import nbformat

    from lantern_jax.core.progress import HAS_WIDGETS

    share = _install_kernelspec(tmp_path / "kernel")
    monkeypatch.setenv("JUPYTER_PATH", str(share))
    code = ("import lantern_jax.apps.evaluation as ev, lantern_jax.apps.stream as st\n"
            "print(type(ev.tqdm(total=1, disable=True)).__module__, ev.tqdm is st.tqdm)")
    nb = nbformat.v4.new_notebook(cells=[nbformat.v4.new_code_cell(code)])
    nbclient.NotebookClient(nb, timeout=300, kernel_name=KERNEL_NAME).execute()
    text = "\n".join(_text(o) for o in _outputs(nb))
    assert "Warning" not in text, text
    assert text.split() == ["tqdm.notebook" if HAS_WIDGETS else "tqdm.std", "True"], text


@pytest.mark.slow
def test_quickstart_notebook_runs(tmp_path, monkeypatch):
    text, n_images = _clean_run("quickstart.py", tmp_path, monkeypatch)
    assert "Overall" in text
    assert "Model (condition)" in text  # the text tables of lantern_jax.report
    assert "SMALL = True" in text
    assert "d soft CUS / d crossing speed" in text
    assert n_images >= 3, f"{n_images} PNG outputs (bird's-eye views and timeline expected)"


@pytest.mark.slow
def test_stress_testing_notebook_runs(tmp_path, monkeypatch):
    text, n_images = _clean_run("stress_testing.py", tmp_path, monkeypatch)
    assert "SMALL = True" in text
    assert "failure_rate" in text and "cmaes" in text  # the comparison table
    assert "restart" in text and "CUS" in text  # the found failures
    assert n_images >= 1, "the convergence plot"


@pytest.mark.slow
def test_train_and_evaluate_notebook_runs(tmp_path, monkeypatch):
    text, n_images = _clean_run("train_and_evaluate.py", tmp_path, monkeypatch)
    assert "SMALL = True" in text
    assert "LANTERN open-loop dataset" in text  # the dataset card
    assert "best_val_l1_m" in text
    assert "nb-coop (warning gain)" in text  # the closed-loop family table
    assert n_images >= 1, "the learning curves"
