"""Open a report in a real headless browser (Debian's Chromium through Selenium's ChromeDriver).

``rendered(report)`` returns what the page showed — its title, every image with whether it
loaded, and the text — or raises :class:`NoBrowser` saying why there is no browser here;
the tests turn that into a visible skip.
"""

from __future__ import annotations

import shutil
from pathlib import Path


class NoBrowser(Exception):
    pass


def _binaries() -> tuple[str, str]:
    chrome = next((p for p in (shutil.which(n) for n in ("chromium", "chromium-browser", "google-chrome")) if p), None)
    driver = shutil.which("chromedriver")
    if chrome is None or driver is None:
        raise NoBrowser("no Chromium/ChromeDriver here (Debian: apt-get install chromium chromium-driver; "
                        "`make test` installs them where it may)")
    return chrome, driver


def rendered(report: Path) -> dict:
    try:
        from selenium import webdriver
        from selenium.webdriver.chrome.service import Service
    except ImportError as exc:  # pragma: no cover
        raise NoBrowser(f"selenium is not installed ({exc})") from None
    chrome, driver_path = _binaries()
    options = webdriver.ChromeOptions()
    options.binary_location = chrome
    for flag in ("--headless=new", "--no-sandbox", "--disable-gpu", "--disable-dev-shm-usage",
                 "--allow-file-access-from-files"):
        options.add_argument(flag)
    driver = webdriver.Chrome(service=Service(driver_path), options=options)
    try:
        driver.set_page_load_timeout(60)
        driver.get(Path(report).resolve().as_uri())
        images = driver.execute_script(
            "return Array.from(document.images).map(i => [i.getAttribute('src'), i.complete && i.naturalWidth > 0]);")
        return {"title": driver.title, "images": images,
                "text": driver.execute_script("return document.body.innerText;")}
    finally:
        driver.quit()
