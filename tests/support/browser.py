"""A real headless Chromium for the live map's tests: Debian's ``chromium`` driven by its
``chromium-driver`` through selenium (no driver is downloaded: the executable is named).
Where either is missing the tests are skipped, and the run's summary says so loudly
(tests/conftest.py): ``apt-get install chromium chromium-driver`` installs both."""

from __future__ import annotations

import os
import shutil
import tempfile
import time
from typing import Any, Callable, Iterator

SKIP_REASON = ("no Chromium for the live map's browser tests: install Debian's chromium and chromium-driver "
               "(apt-get install --no-install-recommends chromium chromium-driver), or set CHROMIUM and CHROMEDRIVER")


def executables() -> tuple[str, str] | None:
    """(chromium, chromedriver), from CHROMIUM / CHROMEDRIVER or the PATH; None if either is missing."""
    browser = os.environ.get("CHROMIUM") or shutil.which("chromium") or shutil.which("chromium-browser")
    driver = os.environ.get("CHROMEDRIVER") or shutil.which("chromedriver")
    return (browser, driver) if browser and driver else None


def chromium(width: int = 1280, height: int = 800) -> Iterator[Any]:
    """A headless Chromium (selenium WebDriver) in a fresh profile, quit at the end. Flags:
    no sandbox (the tests may run as root), and none of Chromium's own background traffic
    (this machine has no network beyond loopback)."""
    from selenium import webdriver
    from selenium.webdriver.chrome.service import Service

    found = executables()
    assert found is not None, SKIP_REASON
    profile = tempfile.mkdtemp(prefix="chromium-")
    options = webdriver.ChromeOptions()
    options.binary_location = found[0]
    for flag in ("--headless=new", "--no-sandbox", "--disable-gpu", "--disable-dev-shm-usage",
                 "--disable-background-networking", "--disable-component-update", "--disable-sync",
                 "--no-first-run", "--disable-default-apps", f"--window-size={width},{height}",
                 f"--user-data-dir={profile}"):
        options.add_argument(flag)
    options.set_capability("goog:loggingPrefs", {"browser": "ALL"})
    driver = webdriver.Chrome(options=options, service=Service(found[1]))
    try:
        yield driver
    finally:
        driver.quit()
        shutil.rmtree(profile, ignore_errors=True)


def wait_for(check: Callable[[], Any], timeout_s: float, what: str | Callable[[], str]) -> Any:
    """``check()``'s first true value, polled; fails naming ``what`` after ``timeout_s``."""
    deadline = time.monotonic() + timeout_s
    while True:
        value = check()
        if value:
            return value
        assert time.monotonic() < deadline, f"not within {timeout_s} s: {what() if callable(what) else what}"
        time.sleep(0.05)


def console_errors(driver: Any) -> list[str]:
    """The page's console errors so far (a 401 the page expects is not one of its errors)."""
    return [e["message"] for e in driver.get_log("browser")
            if e["level"] == "SEVERE" and "401" not in e["message"]]
