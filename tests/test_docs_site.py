"""The documentation site renders in a browser: its home page and an API page open in headless
Chromium with no console error, no uncaught exception and no resource that fails to load.

The site is one built beforehand where ``LANTERN_DOCS_HTML`` names its folder; without it the
test builds one itself, warnings as errors, without executing the notebooks.  It skips, saying
why, where Chromium (Debian's ``chromium``) or the ``docs`` extra (Sphinx, MyST-NB, Furo,
jupytext) is not installed; the browser is looked for first, so a machine without it builds
nothing.  Both tests are marked slow.  Chromium is driven over its DevTools pipe
(``--remote-debugging-pipe``), so no package beyond the browser is needed.
"""

from __future__ import annotations

import contextlib
import fcntl
import importlib
import json
import os
import select
import shutil
import signal
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
CHROMIUM_NAMES = ("chromium", "chromium-browser", "google-chrome")
#: s, how long a tab's first navigation may stay silent before it is navigated again: a local
#: page loads in about a second, in a few with both cores busy.
FIRST_LOAD_WAIT_S = 20.0
CHROMIUM_FLAGS = (
    "--headless", "--no-sandbox", "--disable-gpu", "--disable-quic", "--no-first-run",
    "--disable-background-networking", "--disable-component-update", "--disable-sync",
    "--remote-debugging-pipe", "--window-size=1280,900",
)  # fmt: skip


def _chromium() -> str | None:
    exe = os.environ.get("LANTERN_CHROMIUM")
    if exe:
        return exe
    return next((p for p in map(shutil.which, CHROMIUM_NAMES) if p), None)


class Browser:
    """Headless Chromium spoken to over the DevTools protocol on file descriptors 3 and 4."""

    def __init__(self, exe: str, profile: Path):
        to_chrome_r, self._w = os.pipe()
        self._r, from_chrome_w = os.pipe()
        # The child's ends become its fds 3 and 4 in a small single-threaded Python process
        # that then becomes Chromium (exec), not in a ``preexec_fn``: Python code between fork
        # and exec can deadlock in a process with other threads (JAX's), leaving a child that
        # never starts Chromium.  They are first moved to 10 and above, so that neither dup2
        # overwrites the other end.
        a = fcntl.fcntl(to_chrome_r, fcntl.F_DUPFD, 10)
        b = fcntl.fcntl(from_chrome_w, fcntl.F_DUPFD, 10)
        for fd in (to_chrome_r, from_chrome_w):
            os.close(fd)
        argv = [exe, *CHROMIUM_FLAGS, f"--user-data-dir={profile}", "about:blank"]
        trampoline = (f"import os; os.dup2({a}, 3); os.dup2({b}, 4); os.close({a}); "
                      f"os.close({b}); os.execv({exe!r}, {argv!r})")  # fmt: skip
        self.proc = subprocess.Popen(
            [sys.executable, "-S", "-c", trampoline],
            stdin=subprocess.DEVNULL, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL,
            pass_fds=(a, b), start_new_session=True,  # its own group: close() ends its helpers
        )  # fmt: skip
        os.close(a)
        os.close(b)
        self._buf, self._id, self.events = b"", 0, []

    def _read(self, timeout: float) -> list[dict]:
        ready, _, _ = select.select([self._r], [], [], max(timeout, 0.0))
        if not ready:
            return []
        chunk = os.read(self._r, 1 << 20)
        if not chunk:
            raise RuntimeError("Chromium closed its DevTools pipe")
        self._buf += chunk
        msgs = []
        while b"\0" in self._buf:
            raw, self._buf = self._buf.split(b"\0", 1)
            msgs.append(json.loads(raw))
        return msgs

    def wait(self, done, timeout: float = 60.0) -> dict:
        end = time.monotonic() + timeout
        while time.monotonic() < end:
            for m in self._read(end - time.monotonic()):
                if "id" not in m:
                    self.events.append(m)
                if done(m):
                    if "error" in m:
                        raise RuntimeError(m["error"])
                    return m
        raise TimeoutError("no answer from Chromium")

    def send(self, method: str, params: dict | None = None, session: str | None = None) -> dict:
        self._id += 1
        msg = {"id": self._id, "method": method, "params": params or {}}
        if session:
            msg["sessionId"] = session
        os.write(self._w, json.dumps(msg).encode() + b"\0")
        want = self._id
        return self.wait(lambda m: m.get("id") == want).get("result", {})

    def navigate(self, url: str, sid: str, timeout: float = 60.0) -> None:
        """Navigate the session's tab to ``url`` and wait for its load event.  The event can
        arrive before Chromium answers ``Page.navigate`` (a small local page under load): then
        :meth:`send` has already stored it among the events, and it is taken from there.  A tab
        that sends no load event within :data:`FIRST_LOAD_WAIT_S` (seen in fresh-clone runs
        with both cores busy, twice: once here, once in ``tests/test_report_page.py``, where
        the 60 s it then waited were most of the default tier's longest test) is navigated once
        more and given ``timeout``; a second silence, or a navigation Chromium refuses, is an
        error naming the URL and the events the tab did send.  Before each of those, the tab
        is asked whether its document has loaded anyway (:meth:`_loaded_anyway`): in one
        fresh-clone run the tab reported its frame had stopped loading, and no load event,
        after both navigations."""

        def loaded(m: dict) -> bool:
            return m.get("method") == "Page.loadEventFired" and m.get("sessionId") == sid

        first_wait = min(timeout, FIRST_LOAD_WAIT_S)
        for attempt in (1, 2):
            first = len(self.events)
            result = self.send("Page.navigate", {"url": url}, session=sid)
            if result.get("errorText"):
                raise RuntimeError(f"Chromium could not open {url}: {result['errorText']}")
            if any(loaded(m) for m in self.events[first:]):
                return
            try:
                self.wait(loaded, first_wait if attempt == 1 else timeout)
                return
            except TimeoutError:
                if self._loaded_anyway(sid):
                    return
                if attempt == 2:
                    seen = sorted({str(m.get("method")) for m in self.events[first:]
                                   if m.get("sessionId") == sid})  # fmt: skip
                    raise TimeoutError(f"{url} did not load in {first_wait:.0f} s, nor in "
                                       f"{timeout:.0f} s more; the tab reported "
                                       f"{seen or 'nothing'}") from None  # fmt: skip

    def _loaded_anyway(self, sid: str) -> bool:
        """Whether the session's tab holds a document other than the blank start page whose
        loading is complete (``document.readyState``), its load event missed."""
        answer = self.send(
            "Runtime.evaluate",
            {"expression": "JSON.stringify([document.readyState, location.href])",
             "returnByValue": True},
            session=sid,
        ).get("result", {})  # fmt: skip
        state, href = json.loads(answer.get("value") or '["", ""]')
        return state == "complete" and href != "about:blank"

    def open(self, url: str) -> tuple[list[str], dict]:
        """Load ``url`` in a new tab; returns (problems reported while it loaded, facts about
        the page: title, text length, the main heading)."""
        target = self.send("Target.createTarget", {"url": "about:blank"})["targetId"]
        session = self.send("Target.attachToTarget", {"targetId": target, "flatten": True})
        sid = session["sessionId"]
        for domain in ("Runtime.enable", "Log.enable", "Page.enable"):
            self.send(domain, session=sid)
        first = len(self.events)
        self.navigate(url, sid)
        end = time.monotonic() + 1.0  # late scripts (search index, theme) report here
        while time.monotonic() < end:
            self.events.extend(m for m in self._read(end - time.monotonic()) if "id" not in m)
        facts = self.send(
            "Runtime.evaluate",
            {"expression": "JSON.stringify({title: document.title, "
                           "text: document.body.innerText.length, "
                           "h1: (document.querySelector('h1') || {}).textContent || ''})",
             "returnByValue": True},
            session=sid,
        )["result"]["value"]  # fmt: skip
        problems = [_problem(e) for e in self.events[first:] if e.get("sessionId") == sid]
        self.send("Target.closeTarget", {"targetId": target})
        return [p for p in problems if p], json.loads(facts)

    def close(self) -> None:
        """Ask the browser to quit (it then stops writing to its profile), and end its whole
        process group (zygote, renderers, crash handler) if it has not within 10 s."""
        self._id += 1
        with contextlib.suppress(OSError):  # no answer awaited: the browser closes the pipe
            quit_msg = {"id": self._id, "method": "Browser.close"}
            os.write(self._w, json.dumps(quit_msg).encode() + b"\0")
        try:
            self.proc.wait(timeout=10)
        except subprocess.TimeoutExpired:
            pass
        with contextlib.suppress(ProcessLookupError):
            os.killpg(self.proc.pid, signal.SIGKILL)
        self.proc.wait(timeout=30)
        os.close(self._w)
        os.close(self._r)


def _problem(event: dict) -> str | None:
    """A console error, an uncaught exception or a failed load, as one line; else None."""
    method, p = event.get("method"), event.get("params", {})
    if method == "Runtime.exceptionThrown":
        d = p["exceptionDetails"]
        return f"exception: {d.get('exception', {}).get('description') or d.get('text')}"
    if method == "Runtime.consoleAPICalled" and p.get("type") in ("error", "assert"):
        return "console.error: " + " ".join(
            str(a.get("value", a.get("description"))) for a in p.get("args", [])
        )
    if method == "Log.entryAdded" and p["entry"].get("level") == "error":
        e = p["entry"]
        return f"{e.get('source')}: {e.get('text')} {e.get('url', '')}".strip()
    return None


@pytest.fixture(scope="module")
def site(tmp_path_factory) -> Path:
    """The built site's folder: ``LANTERN_DOCS_HTML`` if it holds one, else a fresh build."""
    built = os.environ.get("LANTERN_DOCS_HTML")
    if built and (Path(built) / "index.html").is_file():
        return Path(built)
    for module in ("sphinx", "myst_nb", "furo", "jupytext"):
        try:
            importlib.import_module(module)
        except ImportError as e:  # missing, or installed but broken
            pytest.skip(f"the docs extra is not usable (pip install -e '.[docs]'): {e}")
    out = tmp_path_factory.mktemp("site") / "html"
    cmd = [sys.executable, "-m", "sphinx", "-W", "--keep-going", "-q", "-b", "html",
           "-D", "nb_execution_mode=off", str(ROOT / "docs"), str(out)]  # fmt: skip
    res = subprocess.run(cmd, capture_output=True, text=True, timeout=1200, cwd=ROOT)
    assert res.returncode == 0, res.stderr[-4000:]
    return out


@pytest.fixture(scope="module")
def browser():
    exe = _chromium()
    if exe is None:
        pytest.skip("Chromium is not installed (apt-get install chromium, or set LANTERN_CHROMIUM)")
    # a helper process the kill missed may still write to the profile as it is removed: the
    # leftover temporary folder is harmless, an error there would fail a test that passed
    with tempfile.TemporaryDirectory(ignore_cleanup_errors=True) as profile:
        b = Browser(exe, Path(profile))
        try:
            yield b
        finally:
            b.close()


def _api_page(site: Path) -> Path:
    pages = sorted((site / "_autosummary").glob("lantern_jax.*.html"))
    assert pages, "the API reference holds no module page"
    preferred = site / "_autosummary" / "lantern_jax.apps.evaluation.html"
    return preferred if preferred in pages else pages[0]


@pytest.mark.slow
def test_home_page_renders(browser, site):
    problems, facts = browser.open((site / "index.html").as_uri())
    assert not problems, problems
    assert "lantern_jax" in facts["title"]
    assert "lantern_jax" in facts["h1"]
    assert facts["text"] > 1000, facts


@pytest.mark.slow
def test_an_api_page_renders(browser, site):
    page = _api_page(site)
    problems, facts = browser.open(page.as_uri())
    assert not problems, (page.name, problems)
    assert page.stem in facts["h1"], facts
    assert facts["text"] > 500, facts


@pytest.mark.slow
def test_no_page_names_the_folder_the_site_was_built_from(site):
    """A value the API reference shows (a module's repr, a default path) would print the build
    machine's folders; such values are documented without them (``:meta hide-value:``).  The
    executed notebooks' pages are left out: their outputs are what the kernels printed."""
    pages = [p for p in site.rglob("*.html") if "notebooks" not in p.relative_to(site).parts]
    assert len(pages) > 100
    named = [str(p.relative_to(site)) for p in pages if str(ROOT) in p.read_text()]
    assert not named, named
