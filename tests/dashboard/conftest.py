"""The dashboard served by `utrf dashboard` (a subprocess, its own emulated board) and pages in
Debian's headless chromium driven by Selenium (tools/setup.sh installs chromium and
chromium-driver; browsers cannot be downloaded). Screenshots go to build/dashboard/."""

from __future__ import annotations

import contextlib
import json
import os
import shutil
import signal
import socket
import subprocess
import sys
import tempfile
import time
import urllib.request
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

import pytest
from selenium import webdriver
from selenium.common.exceptions import (
    ElementNotInteractableException,
    StaleElementReferenceException,
    WebDriverException,
)
from selenium.webdriver.chrome.service import Service
from selenium.webdriver.common.by import By
from selenium.webdriver.remote.webdriver import WebDriver
from selenium.webdriver.support.ui import WebDriverWait

REPO = Path(__file__).resolve().parents[2]
SHOTS = REPO / "build" / "dashboard"
CHROMIUM = "/usr/bin/chromium"
CHROMEDRIVER = "/usr/bin/chromedriver"
CHROME_FLAGS = [
    *("--headless", "--no-sandbox", "--disable-gpu", "--disable-quic", "--no-first-run"),
    *("--disable-background-networking", "--disable-component-update", "--disable-sync"),
    "--enable-unsafe-swiftshader",  # three.js: WebGL in software
    "--window-size=1400,1000",
]


def free_port(host: str = "127.0.0.1") -> int:
    with socket.socket() as s:
        s.bind((host, 0))
        return int(s.getsockname()[1])


class Dashboard:
    """A `utrf dashboard` process and its address."""

    def __init__(self, elf: Path, tmp: Path, host: str = "127.0.0.1", token: str | None = None):
        self.port = free_port(host)
        self.base = f"http://{host}:{self.port}"
        self.token = token
        cmd = [sys.executable, "-m", "utrf", "dashboard", "--elf", str(elf), "--host", host,
               "--http-port", str(self.port), "--rate", "200", "--record-dir", str(tmp),
               "--ui-hz", "5", "--plot-hz", "2",  # light: the machine is shared
               "--hold-after", "8"]  # fmt: skip  # a page starved for seconds is not closed
        if token:
            cmd += ["--token", token]
        self.log_path = tmp / f"dashboard-{self.port}.log"
        self.log = self.log_path.open("w")
        # NiceGUI takes PYTEST_CURRENT_TEST for its own test fixtures' server: not this one
        env = {k: v for k, v in os.environ.items() if k != "PYTEST_CURRENT_TEST"}
        self.proc = subprocess.Popen(
            cmd, stdout=self.log, stderr=subprocess.STDOUT, cwd=tmp, env=env
        )
        deadline = time.monotonic() + 90
        while "utrf dashboard: open" not in self.output():
            if self.proc.poll() is not None or time.monotonic() > deadline:
                self.stop()
                pytest.fail(f"utrf dashboard did not start:\n{self.output()}")
            time.sleep(0.2)

    def output(self) -> str:
        return self.log_path.read_text()

    def status(self) -> dict[str, Any]:
        query = f"?token={self.token}" if self.token else ""
        with urllib.request.urlopen(f"{self.base}/api/status{query}", timeout=5) as r:
            return json.loads(r.read())

    def wait_status(
        self, test: Callable[[dict[str, Any]], bool], timeout: float = 60.0
    ) -> dict[str, Any]:
        deadline = time.monotonic() + timeout
        st = self.status()
        while not test(st):
            if time.monotonic() > deadline:
                pytest.fail(f"the board's telemetry never showed it: {st}")
            time.sleep(0.1)
            st = self.status()
        return st

    def stop(self) -> None:
        if self.proc.poll() is None:
            self.proc.send_signal(signal.SIGINT)
            try:
                self.proc.wait(15)
            except subprocess.TimeoutExpired:
                self.proc.kill()
                self.proc.wait()
        self.log.close()


@pytest.fixture(scope="module")
def dashboard(firmware_elf: Path, tmp_path_factory: pytest.TempPathFactory) -> Iterator[Dashboard]:
    d = Dashboard(firmware_elf, tmp_path_factory.mktemp("dashboard"))
    yield d
    d.stop()


@pytest.fixture(scope="module")
def browser() -> Iterator[Callable[[], WebDriver]]:
    """``browser()``: a new headless chromium (a fresh profile each), quit at the end."""
    if not (shutil.which(CHROMIUM) and shutil.which(CHROMEDRIVER)):
        pytest.fail("Debian's chromium and chromium-driver are missing: run `make setup`")
    drivers: list[WebDriver] = []
    profiles: list[str] = []

    def start() -> WebDriver:
        options = webdriver.ChromeOptions()
        options.binary_location = CHROMIUM
        for flag in CHROME_FLAGS:
            options.add_argument(flag)
        profiles.append(tempfile.mkdtemp(prefix="utrf-chromium-"))
        options.add_argument(f"--user-data-dir={profiles[-1]}")
        d = webdriver.Chrome(options=options, service=Service(CHROMEDRIVER))
        d.implicitly_wait(0)
        drivers.append(d)
        return d

    yield start
    for d in drivers:
        with contextlib.suppress(WebDriverException):
            d.quit()
    for p in profiles:
        shutil.rmtree(p, ignore_errors=True)


def text_of(driver: WebDriver, css: str) -> str:
    for _ in range(20):
        try:
            return driver.find_element(By.CSS_SELECTOR, css).text
        except StaleElementReferenceException:
            time.sleep(0.05)
    return driver.find_element(By.CSS_SELECTOR, css).text


def wait_text(driver: WebDriver, css: str, part: str, timeout: float = 60.0) -> str:
    """The text of ``css`` once it contains ``part``."""
    WebDriverWait(driver, timeout, ignored_exceptions=(StaleElementReferenceException,)).until(
        lambda d: part in text_of(d, css)
    )
    return text_of(driver, css)


def wait_connected(driver: WebDriver, timeout: float = 60.0) -> None:
    """Until the page's websocket is up (a click while it is down is lost, as in any page)."""
    WebDriverWait(driver, timeout).until(
        lambda d: d.execute_script("return !!(window.socket && window.socket.connected)")
    )


def click(driver: WebDriver, css: str, timeout: float = 15.0) -> None:
    """Click once the element takes clicks: the page redraws it (stale) and enables it
    (not interactable) when the server's state reaches it, later on a loaded machine."""
    wait_connected(driver)
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        try:
            driver.find_element(By.CSS_SELECTOR, css).click()
            return
        except (StaleElementReferenceException, ElementNotInteractableException):
            time.sleep(0.1)
    driver.find_element(By.CSS_SELECTOR, css).click()


def screenshot(driver: WebDriver, name: str) -> Path:
    SHOTS.mkdir(parents=True, exist_ok=True)
    path = SHOTS / f"{name}.png"
    driver.save_screenshot(str(path))
    return path
