"""Fixtures of the browser console's tests: one headless Chromium per module (Debian's chromium
and chromium-driver, driven by Selenium with that driver: nothing is downloaded). The consoles
run as real ``zkzap web`` subprocesses against simulators served over TCP from the test process,
so the tests see the device (helpers in ``tests/webpage.py``).
"""

from __future__ import annotations

import os
import shutil
import tempfile

import pytest

from webpage import CHROMEDRIVER, CHROMIUM, CHROMIUM_ARGS


@pytest.fixture(scope="module")
def browser():
    """One headless Chromium for the module's tests (a fresh profile; the console's messages
    kept for :func:`console_errors`)."""
    if not (os.path.exists(CHROMIUM) and os.path.exists(CHROMEDRIVER)):
        pytest.skip("chromium and chromium-driver are not installed (apt-get install chromium chromium-driver)")
    webdriver = pytest.importorskip("selenium.webdriver")
    from selenium.webdriver.chrome.service import Service

    profile = tempfile.mkdtemp(prefix="zkzap-chromium-")
    options = webdriver.ChromeOptions()
    options.binary_location = CHROMIUM
    for a in CHROMIUM_ARGS:
        options.add_argument(a)
    options.add_argument(f"--user-data-dir={profile}")
    options.set_capability("goog:loggingPrefs", {"browser": "ALL"})
    driver = webdriver.Chrome(service=Service(executable_path=CHROMEDRIVER), options=options)
    driver.implicitly_wait(0)
    try:
        yield driver
    finally:
        driver.quit()
        shutil.rmtree(profile, ignore_errors=True)
