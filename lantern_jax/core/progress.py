"""The progress bar of every long-running call (evaluation, streaming, dataset generation,
training).

``tqdm.auto`` draws a notebook widget inside Jupyter, but where ``ipywidgets`` is not installed
(the project does not require it) it warns on import ("TqdmWarning: IProgress not found ...",
naming the installed package's path) before falling back to the text bar; that warning used to
open every notebook's first output.  :data:`tqdm` is ``tqdm.auto``'s class where ``ipywidgets``
can be imported and the text bar (``tqdm.std``) where it cannot, which is what ``tqdm.auto``
falls back to: the same bars, without the warning.
"""

from __future__ import annotations

import importlib.util

#: True where ``ipywidgets`` is installed (only then can Jupyter draw the widget bar).
HAS_WIDGETS = importlib.util.find_spec("ipywidgets") is not None

if HAS_WIDGETS:
    from tqdm.auto import tqdm
else:
    from tqdm.std import tqdm

__all__ = ["HAS_WIDGETS", "tqdm"]
