"""A real browser (headless Chromium) loads Meshcat during a run and sees the robot."""

import subprocess
import tempfile
import threading
import time

import numpy as np
from PIL import Image
from pydrake.geometry import Meshcat, MeshcatParams
from pydrake.systems.analysis import Simulator

from rtcohand_drake.browser import HEADLESS_FLAGS, find_chromium, screenshot
from rtcohand_drake.diagram import build_run_diagram
from rtcohand_drake.scenario import load_scenario
from rtcohand_drake.station import GEN3_LINKS


def _retry(call, attempts=2):
    """Headless Chromium's virtual-time budget sometimes never runs out while the page keeps
    receiving Meshcat's updates; a fresh start then loads in seconds. Try again on a hang."""
    for attempt in range(attempts):
        try:
            return call()
        except subprocess.TimeoutExpired:
            if attempt == attempts - 1:
                raise


def test_meshcat_page_shows_the_gen3_during_a_run(tmp_path):
    chromium = find_chromium()
    meshcat = Meshcat(MeshcatParams(host="localhost", port=0))
    run = build_run_diagram(load_scenario("inspection"), meshcat=meshcat)
    simulator = Simulator(run.diagram)
    simulator.set_target_realtime_rate(1.0)
    simulator.Initialize()
    found = {}
    url = meshcat.web_url()  # every Meshcat call stays on the main thread

    def dump_dom():
        with tempfile.TemporaryDirectory() as profile:
            return subprocess.run([chromium, *HEADLESS_FLAGS, f"--user-data-dir={profile}",
                                   "--virtual-time-budget=8000", "--dump-dom", url],
                                  capture_output=True, text=True, timeout=120).stdout

    def browse():  # the browser works in a thread; Meshcat is driven from the main thread, as it must be
        time.sleep(1.0)  # the run is under way when the page loads
        found["dom"] = _retry(dump_dom)
        found["png"] = _retry(lambda: screenshot(url, tmp_path / "meshcat.png", 800, 600, timeout_s=120))

    browser = threading.Thread(target=browse, daemon=True)
    browser.start()
    while browser.is_alive() and simulator.get_context().get_time() < 500.0:  # the run goes on while the page loads
        simulator.AdvanceTo(simulator.get_context().get_time() + 0.25)
    browser.join(timeout=30)
    assert not browser.is_alive(), "the browser did not finish within 500 s of the run"
    assert "dom" in found and "png" in found, "headless Chromium hung on every attempt"
    dom, png = found["dom"], found["png"]

    # The scene tree in the page lists every Gen3 link that has geometry (end_effector_link is a bare frame).
    missing = [link for link in GEN3_LINKS if link != "end_effector_link" and link not in dom]
    assert not missing, f"links missing from the page's scene tree: {missing}"
    # The screenshot is a rendered scene, not a blank page.
    pixels = np.asarray(Image.open(png).convert("L"), dtype=float)
    assert pixels.std() > 10.0
    assert len(np.unique(pixels.astype(np.uint8))) > 50
