"""The live session page in a real headless Chromium, against a real cloud fed by a real edge.

uvicorn serves the cloud on 127.0.0.1; ``darkread edge run --replay`` streams the shipped sample
recording at wall-clock pace; Chromium (Debian's, driven by its chromedriver through Selenium)
opens the page with the key in the URL fragment, follows the session by keyboard, waits for the
text to appear, presses Ask and Speak, and axe-core checks the page. The screenshots go to the
test's temporary folder, or to docs/ui.png and docs/ui-phone.png with ``DARKREAD_UPDATE_DOCS=1``
(a test run leaves the checkout as it found it).
"""

from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys
import time
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

import httpx
import pytest
from pydantic import SecretStr

from darkread.cloud.app import create_app
from darkread.cloud.server import serve_in_thread
from darkread.cloud.settings import Settings
from darkread.core.paths import SAMPLE_RECORDING
from darkread.core.text_metrics import error_rates
from darkread.edge.io.recording import open_recording

pytestmark = pytest.mark.slow

API_KEY = "live-page-key-31c9"
SESSION = "live-page"
REPO = Path(__file__).resolve().parents[2]
AXE = REPO / "tests" / "vendor" / "axe-core" / "axe.min.js"
DOCS_SCREENSHOT = REPO / "docs" / "ui.png"
MAX_CER = 0.05  # the bar of the read test: the page must read the sample as `darkread read` does
CHROMIUM_FLAGS = (
    "--headless", "--no-sandbox", "--disable-gpu", "--disable-quic", "--no-first-run",
    "--disable-background-networking", "--disable-component-update", "--disable-sync",
    "--disable-dev-shm-usage", "--mute-audio", "--autoplay-policy=no-user-gesture-required",
)


def chromium_paths() -> tuple[str, str]:
    browser = shutil.which("chromium") or shutil.which("chromium-browser")
    driver = shutil.which("chromedriver")
    if browser is None or driver is None:
        pytest.skip("Chromium or chromedriver is not installed (make browser-deps installs them when run as root)")
    pytest.importorskip("selenium", reason="selenium is not installed (the dev extra has it)")
    return browser, driver


@pytest.fixture
def browser(tmp_path: Path) -> Iterator[Any]:
    from selenium import webdriver
    from selenium.webdriver.chrome.service import Service

    binary, driver = chromium_paths()
    options = webdriver.ChromeOptions()
    options.binary_location = binary
    options.set_capability("goog:loggingPrefs", {"performance": "ALL"})  # every request, to check the key's path
    for flag in (*CHROMIUM_FLAGS, f"--user-data-dir={tmp_path / 'chromium-profile'}", "--window-size=1280,1000"):
        options.add_argument(flag)
    chrome = webdriver.Chrome(options=options, service=Service(executable_path=driver, log_output=str(tmp_path / "chromedriver.log")))
    chrome.set_script_timeout(60)
    try:
        yield chrome
    finally:
        chrome.quit()


@pytest.fixture
def cloud(tmp_path: Path) -> Iterator[Any]:
    settings = Settings(_env_file=None, data_dir=tmp_path / "cloud", api_key=SecretStr(API_KEY))
    with serve_in_thread(create_app(settings)) as server:
        yield server


def start_edge(ws_url: str, spool: Path, log: Path) -> subprocess.Popen[bytes]:
    """The glasses: the shipped sample replayed at 0.3x wall-clock pace, a slow reader (10 s), so the page
    is seen growing within the page's rate-limited refreshes (one image per 4 s)."""
    with log.open("wb") as out:
        return subprocess.Popen(
            [sys.executable, "-m", "darkread", "edge", "run", "--replay", str(SAMPLE_RECORDING), "--cloud", ws_url,
             "--speed", "0.3", "--lossless", "--spool", str(spool), "--session", SESSION, "--drain-timeout", "60"],
            env=dict(os.environ, DARKREAD_EDGE_UPLINK_API_KEY=API_KEY), stdout=out, stderr=subprocess.STDOUT,
        )


def wait_for(condition: Callable[[], Any], timeout_s: float, what: str) -> Any:
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        value = condition()
        if value:
            return value
        time.sleep(0.2)
    raise AssertionError(f"timed out after {timeout_s:g} s waiting for {what}")


def serious_violations(chrome: Any) -> list[str]:
    """axe-core's serious and critical findings on the page as it is now."""
    chrome.execute_script(AXE.read_text())
    result = chrome.execute_async_script(
        "const done = arguments[arguments.length - 1];"
        "axe.run(document, {resultTypes: ['violations']}).then(r => done(JSON.stringify(r.violations)), e => done(String(e)));"
    )
    violations = json.loads(result)
    return [
        f"{v['id']} ({v['impact']}): {v['help']} at {[n['target'] for n in v['nodes']]}"
        for v in violations if v["impact"] in ("serious", "critical")
    ]


def test_live_page_follows_a_session_reads_and_speaks(browser: Any, cloud: Any, tmp_path: Path) -> None:
    from selenium.webdriver.common.by import By
    from selenium.webdriver.common.keys import Keys

    if shutil.which("espeak-ng") is None:
        pytest.skip("espeak-ng is not installed (make speech-deps installs it when run as root)")
    printed = open_recording(SAMPLE_RECORDING).text
    assert printed

    # Opened before the glasses connect, with the key in the fragment (never sent to the server).
    browser.get(f"{cloud.url}/sessions/{SESSION}#key={API_KEY}")
    wait_for(lambda: "waiting for the glasses" in browser.find_element(By.ID, "status").text, 20, "the waiting page")
    assert "key=" not in browser.current_url  # the key left the address bar (and the history)
    assert serious_violations(browser) == []

    # Line by line, switched on from the keyboard before the glasses connect.
    speak_lines = browser.find_element(By.ID, "speak-lines")
    press_tab_until(browser, speak_lines).send_keys(Keys.SPACE)
    assert speak_lines.is_selected()

    captions: list[str] = []  # the page image as it grows: "N frames, W x H pixels"

    def text_shown() -> str:
        caption = browser.find_element(By.ID, "page-caption").text
        if "frames," in caption and (not captions or captions[-1] != caption):
            captions.append(caption)
        return str(browser.find_element(By.ID, "text").text)

    edge = start_edge(cloud.ws_url, tmp_path / "spool", tmp_path / "edge.log")
    try:
        wait_for(lambda: (text_shown(), edge.poll() is not None)[1], 180, "the edge to finish its replay")
        assert edge.returncode == 0, (tmp_path / "edge.log").read_text()[-2000:]
    finally:
        if edge.poll() is None:
            edge.kill()
            edge.wait(10)
    frames = httpx.get(f"{cloud.url}/v1/sessions/{SESSION}", headers={"X-API-Key": API_KEY}).json()["frames"]
    wait_for(lambda: text_shown() and captions[-1].startswith(f"{frames} frames,"), 60, "the page of the whole replay")
    assert len(captions) >= 2, f"the page image did not grow while frames arrived: {captions}"

    shown = [line for line in browser.find_element(By.ID, "text").text.split("\n") if line.strip()]
    spoken_lines = wait_for(lambda: (n := int(browser.execute_script(
        "return document.getElementById('line-voice').dataset.spoken"))) >= len(shown) and n, 90, "each line spoken")
    assert spoken_lines == len(shown), f"{spoken_lines} lines spoken for {len(shown)} read"  # each once
    early_requests = sent_requests(browser)  # the log is read once: kept for the key checks at the end
    line_calls = [url for url, _ in early_requests if "/lines/" in url and "/speech" in url]
    assert sorted({url.split("/lines/")[1].split("/")[0] for url in line_calls}) == [str(i) for i in range(len(shown))]

    ask = browser.find_element(By.ID, "ask")
    ask.send_keys(Keys.ENTER)  # a native button: Enter presses it
    wait_for(lambda: browser.find_element(By.ID, "answer").get_attribute("data-state") == "done", 120, "the answer")
    answer = browser.find_element(By.ID, "answer-text").text
    rates = error_rates(printed, answer)
    assert rates.cer <= MAX_CER, f"the page answered {answer!r} (CER {rates.cer:.1%})"
    assert error_rates(printed, browser.find_element(By.ID, "text").text).cer <= MAX_CER

    browser.find_element(By.ID, "speak").send_keys(Keys.ENTER)
    seconds = wait_for(lambda: browser.execute_script(
        "const v = document.getElementById('voice'); return v.hidden || !(v.duration > 0) ? 0 : v.duration;"), 120, "the spoken answer")
    words = len(answer.split())
    assert 0.6 * 60 / 140 <= seconds / words <= 1.4 * 60 / 140, f"{seconds:.2f} s for {words} words"
    assert serious_violations(browser) == []
    print(f"live page: {captions}; answer {answer!r} (CER {rates.cer:.1%}); spoken {seconds:.2f} s for {words} words")
    browser.execute_script("document.activeElement.blur(); window.scrollTo(0, 0);")
    screenshot = DOCS_SCREENSHOT if os.environ.get("DARKREAD_UPDATE_DOCS") == "1" else tmp_path / "ui.png"
    whole_page(browser, 1280, screenshot)
    # On a phone: one column, nothing wider than the screen.
    assert whole_page(browser, 390, screenshot.with_name("ui-phone.png")) <= 0
    browser.execute_cdp_cmd("Emulation.clearDeviceMetricsOverride", {})

    # Keyboard only: Tab to "All sessions", Enter; Tab to the session in the list, Enter.
    press_tab_until(browser, browser.find_element(By.LINK_TEXT, "All sessions")).send_keys(Keys.ENTER)
    link = wait_for(lambda: browser.find_elements(By.CSS_SELECTOR, f'[data-session="{SESSION}"]'), 20, "the session list")[0]
    assert f"{frames} frames" in link.text
    assert serious_violations(browser) == []
    press_tab_until(browser, link).send_keys(Keys.ENTER)
    wait_for(lambda: browser.current_url.endswith(f"/sessions/{SESSION}") and text_shown(), 60, "the session again")

    # Without a key in the tab: the login form, a wrong key refused, the right one typed in.
    browser.execute_script("sessionStorage.clear();")
    browser.get(f"{cloud.url}/")
    key_input = wait_for(lambda: [e for e in browser.find_elements(By.ID, "key") if e.is_displayed()], 20, "the login form")[0]
    assert browser.switch_to.active_element == key_input
    key_input.send_keys("not-the-key", Keys.ENTER)
    wait_for(lambda: "not accepted" in browser.find_element(By.ID, "login-error").text, 20, "the wrong key refused")
    assert browser.current_url == f"{cloud.url}/"  # the form never submitted
    key_input.clear()
    key_input.send_keys(API_KEY, Keys.ENTER)
    wait_for(lambda: browser.find_elements(By.CSS_SELECTOR, f'[data-session="{SESSION}"]'), 20, "the list after login")
    assert serious_violations(browser) == []

    requests = early_requests + sent_requests(browser)
    assert requests and not [url for url, _ in requests if API_KEY in url], "the key went into a URL"
    api_calls = [(url, headers) for url, headers in requests if "/v1/" in url or "/ui/sessions" in url]
    assert {headers.get("x-api-key") for _, headers in api_calls} == {API_KEY, "not-the-key", None}
    # without a key (after sessionStorage was cleared) only the probe that shows the login form
    assert {url for url, headers in api_calls if "x-api-key" not in headers} == {f"{cloud.url}/v1/sessions"}


def press_tab_until(chrome: Any, target: Any, most: int = 15) -> Any:
    """Tab from the top of the page until ``target`` has the focus (fails if it never does)."""
    from selenium.webdriver.common.action_chains import ActionChains
    from selenium.webdriver.common.keys import Keys

    chrome.execute_script("document.activeElement.blur(); window.scrollTo(0, 0);")
    for _ in range(most):
        ActionChains(chrome).send_keys(Keys.TAB).perform()
        if chrome.switch_to.active_element == target:
            return target
    raise AssertionError(f"{target.text!r} is not reachable with Tab")


def sent_requests(chrome: Any) -> list[tuple[str, dict[str, str]]]:
    """(URL, lower-case headers) of every request the page made, from Chromium's DevTools network log."""
    requests = []
    for entry in chrome.get_log("performance"):
        message = json.loads(entry["message"])["message"]
        if message["method"] == "Network.requestWillBeSent":
            request = message["params"]["request"]
            requests.append((request["url"], {k.lower(): v for k, v in request.get("headers", {}).items()}))
    return requests


def whole_page(chrome: Any, width: int, path: Path) -> int:
    """Screenshot of the whole page at a viewport ``width`` (CSS px); returns the horizontal overflow."""
    chrome.execute_cdp_cmd("Emulation.setDeviceMetricsOverride", {"width": width, "height": 800, "deviceScaleFactor": 1, "mobile": width < 600})
    height = chrome.execute_script("return document.documentElement.scrollHeight;")
    chrome.execute_cdp_cmd("Emulation.setDeviceMetricsOverride", {"width": width, "height": height, "deviceScaleFactor": 1, "mobile": width < 600})
    path.parent.mkdir(exist_ok=True)
    chrome.save_screenshot(str(path))
    return int(chrome.execute_script("return document.documentElement.scrollWidth - document.documentElement.clientWidth;"))
