"""The HTML report (``lantern-jax report``, :mod:`lantern_jax.report.page`): built from result
folders alone, it holds the run's identity, the plots and sortable tables, the paired
differences of two policies and one gallery row per failing execution of the route CSV; it
opens in headless Chromium with no console error and every image and link resolving."""

from __future__ import annotations

import json
from pathlib import Path

import pandas as pd
import pytest

import lantern_jax as lj
from lantern_jax import cli
from lantern_jax.report.evidence import read_result_set
from lantern_jax.report.page import build_report, failures

PAIRS = ["pe_0001", "vc_0001", "lww_0001", "rty_0002"]


@pytest.fixture(scope="module")
def folder(tmp_path_factory) -> Path:
    """A result folder of two policies on four pairs (ego fails Pedestrian Emergence)."""
    out = tmp_path_factory.mktemp("report") / "results"
    result = lj.evaluate(["ego", "coop"], suite=lj.load_suite().select(PAIRS), progress=False)
    result.write(out)
    return out


def test_failures_are_every_failed_gate_of_the_route_table(folder):
    table = read_result_set(folder).table
    fails = failures(table)
    a_fail = (table[["no_collision", "on_route", "in_lane", "no_red_light", "not_blocked"]] == 0)
    b_fail = (table["no_false_brake"] == 0) & (table["condition"] == "warning")
    assert len(fails) == int(a_fail.any(axis=1).sum() + b_fail.sum())
    assert len(fails) > 0, "the fixture should hold a failure (ego on pe_0001)"
    assert set(fails["route"]) <= {"A", "B"} and fails["cause"].str.len().min() > 5


def test_a_report_holds_the_identity_the_plots_the_tables_and_every_failure(folder, tmp_path):
    out = build_report([folder], tmp_path / "report.html")
    page = out.read_text()
    manifest = json.loads((folder / "reproducibility_manifest.json").read_text())
    assert manifest["suite_sha256"][:12] in page and "lantern-v3" in page
    assert page.count('src="data:image/png;base64,') >= 3  # CUS, gates, forest
    assert page.count('<table class="sortable">') >= 4
    assert "Paired differences" in page and "coop - ego" in page
    fails = failures(read_result_set(folder).table)
    assert page.count('<div class="fail"') == len(fails)
    assert "http://" not in page and "https://" not in page  # nothing to fetch when viewed


def test_the_run_says_how_its_actors_found_the_ego(folder, tmp_path):
    """The run's identity names the actors' ego-leader rule: the default as every new run
    records it; the earlier rule for a manifest written before 2026-12-08 that records none."""
    import shutil

    page = build_report([folder], tmp_path / "default.html").read_text()
    assert "heading_line_or_box (the default)" in page
    older = tmp_path / "older"
    shutil.copytree(folder, older)
    path = older / "reproducibility_manifest.json"
    manifest = json.loads(path.read_text())
    assert manifest["settings"]["actors"] == {"ego_leader": "heading_line_or_box"}
    del manifest["settings"]["actors"]
    path.write_text(json.dumps(manifest))
    page = build_report([older], tmp_path / "older.html").read_text()
    assert "heading_line" in page and "(the default)" not in page


def test_the_command_line_writes_the_report_and_refuses_what_it_cannot(folder, tmp_path):
    out = tmp_path / "r.html"
    assert cli.main(["report", str(folder), "--out", str(out), "--quiet"]) == 0
    assert out.is_file()
    assert cli.main(["report", str(folder), "--out", str(tmp_path / "r.txt")]) == 2
    bad = tmp_path / "bad"
    bad.mkdir()
    (bad / "route_level_results.csv").write_text("x\n")
    assert cli.main(["report", str(bad), "--out", str(tmp_path / "b.html")]) == 2


def test_an_evaluation_writes_its_report(tmp_path):
    result = lj.evaluate(["ego"], suite=lj.load_suite().select(PAIRS[:2]), progress=False)
    path = result.report(tmp_path / "mine.html")
    assert path.is_file() and (tmp_path / "mine_results" / "route_level_results.csv").is_file()
    assert pd.read_csv(tmp_path / "mine_results" / "route_level_results.csv").shape[0] == 4


def test_the_report_opens_in_a_browser(folder, tmp_path):
    """Headless Chromium loads the page with no console error or failed load, every image
    decoded, and as many gallery rows as the route CSV has failing executions."""
    from test_docs_site import Browser, _chromium

    exe = _chromium()
    if exe is None:
        pytest.skip("Chromium is not installed (apt-get install chromium, or set LANTERN_CHROMIUM)")
    out = build_report([folder], tmp_path / "report.html")
    browser = Browser(exe, tmp_path / "profile")
    try:
        problems, facts = _open(browser, out.as_uri())
    finally:
        browser.close()
    assert not problems, problems
    assert facts["h1"].startswith("lantern_jax report") and facts["text"] > 500
    assert facts["images"] >= 3 and facts["broken"] == 0, facts
    assert facts["rows"] == failures(read_result_set(folder).table).shape[0], facts
    assert facts["sorted"], "a click on a header sorts its table"


#: What the browser reports about the page: images decoded, gallery rows, and whether a click on
#: the first table's second header reorders its rows.
_FACTS = """JSON.stringify((function () {
  var imgs = Array.from(document.images);
  var t = document.querySelector('table.sortable'), before = t.tBodies[0].innerHTML;
  t.tHead.rows[0].cells[1].click();
  var after = t.tBodies[0].innerHTML;
  t.tHead.rows[0].cells[1].click();
  return {title: document.title, text: document.body.innerText.length,
          h1: (document.querySelector('h1') || {}).textContent || '',
          images: imgs.length,
          broken: imgs.filter(function (i) { return !i.complete || !i.naturalWidth; }).length,
          rows: document.querySelectorAll('div.fail').length,
          sorted: t.tBodies[0].rows.length < 2 || before !== after ||
                  t.tBodies[0].innerHTML !== before};
})())"""


def _open(browser, url: str) -> tuple[list[str], dict]:
    """Load ``url`` in a new tab; (problems reported while it loaded, :data:`_FACTS`)."""
    import time

    from test_docs_site import _problem

    target = browser.send("Target.createTarget", {"url": "about:blank"})["targetId"]
    sid = browser.send("Target.attachToTarget", {"targetId": target, "flatten": True})["sessionId"]
    for domain in ("Runtime.enable", "Log.enable", "Page.enable"):
        browser.send(domain, session=sid)
    first = len(browser.events)
    browser.navigate(url, sid)
    end = time.monotonic() + 1.0
    while time.monotonic() < end:
        browser.events.extend(m for m in browser._read(end - time.monotonic()) if "id" not in m)
    value = browser.send("Runtime.evaluate", {"expression": _FACTS, "returnByValue": True},
                         session=sid)["result"]["value"]  # fmt: skip
    problems = [_problem(e) for e in browser.events[first:] if e.get("sessionId") == sid]
    browser.send("Target.closeTarget", {"targetId": target})
    return [p for p in problems if p], json.loads(value)


def test_a_report_of_two_result_folders_compares_them(folder, tmp_path):
    """Two runs (here: the folder and a copy) side by side: both identities, every policy of
    both in the plots, and the paired differences across the folders."""
    import shutil

    other = tmp_path / "rerun"
    shutil.copytree(folder, other)
    page = build_report([folder, other], tmp_path / "two.html").read_text()
    assert page.count("<dt>folder</dt>") == 2
    assert "coop (rerun) - ego (results)" in page
    assert page.count('<div class="fail"') == 2 * len(failures(read_result_set(folder).table))


def test_a_page_chromium_cannot_open_is_named(tmp_path):
    """The browser helper names a URL that Chromium refuses to load, with Chromium's error,
    instead of waiting for a load event that never comes."""
    from test_docs_site import Browser, _chromium

    exe = _chromium()
    if exe is None:
        pytest.skip("Chromium is not installed (apt-get install chromium, or set LANTERN_CHROMIUM)")
    browser = Browser(exe, tmp_path / "profile")
    try:
        target = browser.send("Target.createTarget", {"url": "about:blank"})["targetId"]
        sid = browser.send("Target.attachToTarget", {"targetId": target, "flatten": True})
        missing = (tmp_path / "missing.html").as_uri()
        with pytest.raises(RuntimeError, match=r"could not open .*missing\.html: net::ERR_FILE"):
            browser.navigate(missing, sid["sessionId"])
    finally:
        browser.close()
