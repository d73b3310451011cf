"""A real browser (headless Chromium) loads Meshcat during a run and sees the robot."""

import subprocess
import tempfile

import numpy as np
from PIL import Image
from pydrake.geometry import Meshcat, MeshcatParams
from pydrake.systems.analysis import Simulator

from rtcohand_drake.browser import HEADLESS_FLAGS, find_chromium, screenshot
from rtcohand_drake.learning.policy_file import reads_path_shape
from rtcohand_drake.diagram import build_run_diagram
from rtcohand_drake.scenario import load_scenario
from rtcohand_drake.cell.plant import GEN3_LINKS
from rtcohand_drake.cell.robot_files import models_dir
from rtcohand_drake.systems.gestures.simulated_person import make_builtin_person
from rtcohand_drake.systems.overlay import lamp_state
from rtcohand_drake.systems.policy import CchpPolicy
from rtcohand_drake.systems.safety.rules import Intervention
from rtcohand_drake.systems.safety.supervisor import Mode


def _retry(call, attempts=2):
    """One more try when headless Chromium hangs."""
    for attempt in range(attempts):
        try:
            return call()
        except subprocess.TimeoutExpired:
            if attempt == attempts - 1:
                raise


def test_meshcat_page_shows_the_gen3_during_a_run(tmp_path):
    """The run is under way (the arm has started lifting) when the page is read.

    Chromium's --virtual-time-budget stalls for a minute or more, or for good, while
    Meshcat streams updates (measured here), so the run holds still while each
    page load happens and goes on between them. Every Meshcat call stays on the main
    thread; Meshcat's own server thread answers the browser.
    """
    chromium = find_chromium()
    meshcat = Meshcat(MeshcatParams(host="localhost", port=0))
    scenario = load_scenario("inspection")
    model = models_dir() / scenario.policy.model
    source, pieces = make_builtin_person(scenario, seed=0, path_shape=reads_path_shape(model))
    policy = CchpPolicy(model, pieces, scenario.policy.rate_hz, seed=0)
    run = build_run_diagram(scenario, source=source, policy=policy, meshcat=meshcat)
    simulator = Simulator(run.diagram)
    simulator.Initialize()
    url = meshcat.web_url()

    def dump_dom():
        with tempfile.TemporaryDirectory() as profile:
            return subprocess.run([chromium, *HEADLESS_FLAGS, f"--user-data-dir={profile}",
                                   "--virtual-time-budget=8000", "--dump-dom", url],
                                  capture_output=True, text=True, timeout=60).stdout

    simulator.AdvanceTo(10.0)  # the person has lifted the part and is moving it
    dom = _retry(dump_dom)
    simulator.AdvanceTo(12.0)
    png = _retry(lambda: screenshot(url, tmp_path / "meshcat.png", 800, 600, timeout_s=60))
    simulator.AdvanceTo(14.0)  # the run goes on after the page was read
    assert simulator.get_context().get_time() == 14.0

    # The scene tree in the page lists every Gen3 link that has geometry (end_effector_link is a bare frame).
    missing = [link for link in GEN3_LINKS if link != "end_effector_link" and link not in dom]
    assert not missing, f"links missing from the page's scene tree: {missing}"
    # The overlay: twist arrows with shafts, heads and uncertainty balls; the six face marks, dim
    # and lit; the status lamp's states, "hand away" among them.
    for name in ("twist", "linear", "angular", "shaft", "head", "uncertainty", "faces", "px", "nz", "dim", "lit",
                 "status_lamp", "running", "paused", "hand_away", "fault"):
        assert f">{name}<" in dom, f"{name} missing from the page's scene tree"
    # The screenshot is a rendered scene, not a blank page.
    pixels = np.asarray(Image.open(png).convert("L"), dtype=float)
    assert pixels.std() > 10.0
    assert len(np.unique(pixels.astype(np.uint8))) > 50


def test_the_lamp_tells_a_hand_away_from_a_fault():
    assert lamp_state(Mode.RUNNING, 0, 1.0) == "running"
    assert lamp_state(Mode.PAUSED, int(Intervention.PAUSED), 0.0) == "paused"
    # The watchdog with no hand in view: a normal pause between strokes.
    assert lamp_state(Mode.WATCHDOG, int(Intervention.WATCHDOG), 0.0) == "hand_away"
    # Non-finite input, or a hand in a feed gone stale: faults.
    assert lamp_state(Mode.WATCHDOG, int(Intervention.WATCHDOG | Intervention.NON_FINITE), 0.0) == "fault"
    assert lamp_state(Mode.WATCHDOG, int(Intervention.WATCHDOG), 1.0) == "fault"
