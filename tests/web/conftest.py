"""Fixtures of the browser console's tests: one headless Chromium for the session of a test
process (Debian's chromium and chromium-driver, driven by Selenium with that driver: nothing is
downloaded). The consoles run as real ``zkzap web`` subprocesses against simulators served over
TCP from the test process, so the tests see the device (helpers in ``tests/webpage.py``).

A module's simulator and console are session fixtures too: pytest-xdist may run a module's tests
between other modules' tests, and a module-scoped console would be ended and started again each
time; a page fixture brings the browser back to its module's console.
"""

from __future__ import annotations

import os
import shutil
import tempfile

import pytest

from webpage import CHROMEDRIVER, CHROMIUM, CHROMIUM_ARGS


@pytest.fixture(scope="session")
def browser():
    """One headless Chromium for the tests (a fresh profile; the console's messages
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


@pytest.hookimpl(hookwrapper=True)
def pytest_runtest_makereport(item, call):
    """A failed browser test's report shows what its page said (toasts, activity, who controls)."""
    outcome = yield
    report = outcome.get_result()
    driver = item.funcargs.get("browser") if hasattr(item, "funcargs") else None
    if report.when in ("setup", "call") and report.failed and driver is not None:
        try:
            said = driver.execute_script(
                "const t = (s) => (document.querySelector(s) || {}).innerText || '';"
                "return {url: location.href, control: t('#control'), busy: t('#busy'), toasts: t('#toasts'),"
                " dialog: t('#modal.show'), log: t('#log').split('\\n').slice(0, 16).join(' | ')};")
        except Exception as e:  # noqa: BLE001 - the browser itself may be what failed
            said = f"(page unreadable: {e})"
        report.sections.append(("the page", str(said)))
