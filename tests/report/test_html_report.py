"""report.html of a run and of a sweep: self-contained pages that a real browser opens from
disk without a console error, every figure rendered with a non-zero size.

The browser checks drive Debian's Chromium through its ChromeDriver with selenium. Where
no browser is installed they skip, saying so, unless ``NLOSFW_REQUIRE_BROWSER=1`` (CI sets
it: ``.ci/run`` installs chromium and chromium-driver), where they fail instead.
"""

import os
import re
import shutil
from pathlib import Path

import pytest

import nlosfw
from nlosfw.pipeline.metrics import RunMetrics
from nlosfw.report.sweep import write_report

CHROMIUM = shutil.which("chromium") or "/usr/bin/chromium"
CHROMEDRIVER = shutil.which("chromedriver") or "/usr/bin/chromedriver"
#: Flags that let headless Chromium run as root on a machine without a network.
CHROMIUM_FLAGS = ("--headless", "--no-sandbox", "--disable-gpu", "--disable-quic",
                  "--no-first-run", "--disable-background-networking",
                  "--disable-component-update", "--disable-sync")
TINY = ["scene=tiny", "transform.n_frequencies=21", "reconstruction.n_depths=4"]


@pytest.fixture(scope="module")
def reports(tmp_path_factory):
    """A run's report.html (with figures) and a two-run sweep's report/report.html."""
    root = tmp_path_factory.mktemp("html")
    with pytest.MonkeyPatch.context() as mp:
        mp.setenv("NLOSFW_CACHE_DIR", str(root / "cache"))
        run = nlosfw.run([*TINY, "model=interp", "+compare.nn={name:nearest}"],
                         output_dir=root / "run")
        for i, model in enumerate(["interp", "nearest"]):
            nlosfw.run([*TINY, f"model={model}", "figures.enabled=false"],
                       output_dir=root / "sweep" / str(i))
        out, _ = write_report(root / "sweep")
    return {"run": run.dir / "report.html", "sweep": out / "report.html", "root": root}


def test_run_page_holds_figures_metrics_timings_and_configuration(reports):
    text = reports["run"].read_text()
    run_dir = reports["run"].parent
    metrics = RunMetrics.read(run_dir / "metrics.json")
    figures = sorted((run_dir / "figures").glob("*.png"))
    views = {f"{view}_{source}.png" for source in metrics.reconstruction.sources
             for view in ("front", "depth", "slices")}
    assert views | {"time_profile.png", "reconstructions.png"} <= {f.name for f in figures}
    assert len(figures) == 5 + len(views) + 1
    assert text.count("<img src=\"data:image/png;base64,") == len(figures)
    assert "<h2>Views</h2>" in text
    assert f"<td>{metrics.reconstruction.sources['nn'].ssim:.4g}</td>" in text
    nmse = metrics.field["interp"].splits.heldout_pixels.nmse_db
    assert f"<td>{nmse:.4g}</td>" in text
    assert "<h2>Timings (s)</h2>" in text and f"<td>{metrics.timings.total:.4g}</td>" in text
    assert "<h2>Configuration</h2>" in text and "spatial_step: 2" in text
    assert "status <b>completed</b>" in text


def test_sweep_page_holds_the_quality_plot_its_numbers_and_links_to_runs(reports):
    text = reports["sweep"].read_text()
    assert text.count("<img src=\"data:image/png;base64,") == 1
    assert "<h3>reconstruction SSIM against the full capture&#x27;s, higher is better</h3>" in text
    for i in ("0", "1"):
        assert f"<a href=\"../{i}/report.html\">{i}</a>" in text
        assert (reports["sweep"].parent / ".." / i / "report.html").resolve().is_file()
    assert "<h2>Timings (s)</h2>" in text and "<td>model</td><td>interp, nearest</td>" in text


@pytest.mark.parametrize("page", ["run", "sweep"])
def test_pages_are_self_contained(reports, page):
    text = reports[page].read_text()
    assert not re.search(r"<script|<link|<iframe|@import|url\(", text, flags=re.I)
    sources = re.findall(r"src=\"([^\"]*)\"", text)
    assert sources and all(s.startswith("data:image/png;base64,") for s in sources)
    hrefs = re.findall(r"href=\"([^\"]*)\"", text)
    assert not [h for h in hrefs if re.match(r"[a-z]+:", h)]   # only relative links


@pytest.fixture(scope="module")
def browser(tmp_path_factory):
    missing = [p for p in (CHROMIUM, CHROMEDRIVER) if not Path(p).is_file()]
    try:
        from selenium import webdriver
        from selenium.webdriver.chrome.service import Service
    except ImportError:
        missing.append("the selenium package (pip install '.[test]')")
    if missing:
        reason = (f"no headless browser to open report.html: missing {', '.join(missing)} "
                  "(apt-get install chromium chromium-driver)")
        if os.environ.get("NLOSFW_REQUIRE_BROWSER") == "1":
            pytest.fail(reason)
        pytest.skip(reason)
    options = webdriver.ChromeOptions()
    options.binary_location = CHROMIUM
    for flag in CHROMIUM_FLAGS:
        options.add_argument(flag)
    options.add_argument(f"--user-data-dir={tmp_path_factory.mktemp('chromium-profile')}")
    options.add_argument("--window-size=1280,1024")
    options.set_capability("goog:loggingPrefs", {"browser": "ALL"})
    driver = webdriver.Chrome(service=Service(CHROMEDRIVER), options=options)
    yield driver
    driver.quit()


@pytest.mark.parametrize("page", ["run", "sweep"])
def test_page_renders_in_a_real_browser(reports, browser, page):
    path = reports[page]
    browser.get_log("browser")                                  # drop earlier entries
    browser.get(path.as_uri())
    assert browser.execute_script("return document.readyState") == "complete"
    assert browser.title.startswith("nlosfw ")
    errors = [e for e in browser.get_log("browser") if e["level"] in ("SEVERE", "WARNING")]
    assert not errors, f"{path}: console errors {errors}"
    images = browser.execute_script(
        "return Array.from(document.images).map(i => ({complete: i.complete, "
        "natural: i.naturalWidth * i.naturalHeight, width: i.getBoundingClientRect().width, "
        "height: i.getBoundingClientRect().height, alt: i.alt}))")
    expected = path.read_text().count("<img ")
    assert len(images) == expected >= 1
    for image in images:
        assert image["complete"] and image["natural"] > 0, f"{image['alt']} did not decode"
        assert image["width"] > 100 and image["height"] > 100, f"{image['alt']}: {image}"
    tables = browser.execute_script("return document.querySelectorAll('table').length")
    assert tables >= 3
