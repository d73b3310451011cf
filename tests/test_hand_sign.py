"""The pause hand sign: a thumbs-up held still toggles the pause, from keypoints; no gesture of the population makes it."""

import numpy as np
import pytest
from pydrake.systems.analysis import Simulator

from rtcohand_drake.data.population import GeneratorConfig, generate_population
from rtcohand_drake.interfaces import HAND_SIGN, KEYPOINTS, OPERATOR
from rtcohand_drake.systems.hand_sign import (PauseHandSign, axis_from_up_deg, initial_state, openness, sign_step,
                                              thumb_elevation_deg)
from rtcohand_drake.systems.hand_sign_config import HandSign
from rtcohand_drake.vision.drawn_hand import open_hand_U, thumbs_up_U

OPEN, THUMBS_UP, LOST = open_hand_U(), thumbs_up_U(), np.full((21, 3), np.nan)


def _play(script, panel_pause=0.0, config=HandSign()):
    """Runs the system alone over `script` [(keypoints (21, 3), seconds)]; the operator output each 0.1 s."""
    system = PauseHandSign(config)
    simulator = Simulator(system)
    context = simulator.get_mutable_context()
    system.GetInputPort(OPERATOR).FixValue(context, [panel_pause, 1.3])
    out, t = [], 0.0
    for keypoints, seconds in script:
        system.GetInputPort(KEYPOINTS).FixValue(context, np.asarray(keypoints, float).reshape(-1))
        for _ in range(int(round(seconds / 0.1))):
            t += 0.1
            simulator.AdvanceTo(t - 0.05)  # between two updates: the state after the one at t - 0.1
            out.append(system.GetOutputPort(OPERATOR).Eval(context).copy())
    return np.array(out), system.GetOutputPort(HAND_SIGN).Eval(context)


def upright_closed_hand(thumb_from_up_deg: float = 15.0) -> np.ndarray:
    """A closed hand held upright (fingers up, palm forward), its thumb laid along the fingers and
    pointing up: how recorded grabs and pinches end."""
    kp = open_hand_U(curl=1.0)
    a = np.radians(thumb_from_up_deg)
    along = np.array([np.sin(a), 0.0, np.cos(a)])
    kp[3], kp[4] = kp[2] + 0.03 * along, kp[2] + 0.055 * along
    return kp


def test_the_two_hands_read_as_intended():
    assert openness(OPEN) > 1.8 and openness(THUMBS_UP) < 1.0
    assert thumb_elevation_deg(THUMBS_UP) < 20.0
    assert axis_from_up_deg(THUMBS_UP) > 80.0  # the fist on its side
    upright = upright_closed_hand()
    assert openness(upright) < 1.0 and thumb_elevation_deg(upright) < 20.0 and axis_from_up_deg(upright) < 10.0
    assert np.isnan(openness(LOST))


def test_thumbs_up_pauses_and_resumes():
    out, sign = _play([(OPEN, 1.0), (THUMBS_UP, 1.0), (OPEN, 1.0), (THUMBS_UP, 1.0), (OPEN, 0.5)])
    pause = out[:, 0]
    assert np.all(out[:, 1] == 1.3)  # the panel's sensitivity passes through
    assert np.all(pause[:15] == 0)  # the sign began at 1.0 s: not yet 0.5 s held
    assert np.all(pause[15:35] == 1)  # paused from 1.5 s (held 0.5 s) ...
    assert np.all(pause[35:] == 0)  # ... resumed 0.5 s into the second sign
    assert sign[2] == 2 and sign[0] == 0


def test_held_sign_toggles_once_and_short_or_moving_signs_never():
    out, _ = _play([(OPEN, 0.5), (THUMBS_UP, 3.0)])
    assert out[-1, 0] == 1 and np.count_nonzero(np.diff(out[:, 0])) == 1
    out, _ = _play([(OPEN, 0.5), (THUMBS_UP, 0.3), (OPEN, 0.3), (THUMBS_UP, 0.3), (OPEN, 0.5)])
    assert np.all(out[:, 0] == 0)
    # Starting with the sign does nothing until the hand has been seen open.
    out, _ = _play([(THUMBS_UP, 2.0)])
    assert np.all(out[:, 0] == 0)
    # A thumbs-up moving 5 cm a tenth of a second is a gesture, not the sign.
    moving = [(THUMBS_UP + [0.05 * (k % 2), 0.0, 0.0], 0.1) for k in range(20)]
    out, _ = _play([(OPEN, 0.5)] + moving)
    assert np.all(out[:, 0] == 0)
    # A lost hand breaks the hold.
    out, _ = _play([(OPEN, 0.5), (THUMBS_UP, 0.3), (LOST, 0.1), (THUMBS_UP, 0.3), (OPEN, 0.3)])
    assert np.all(out[:, 0] == 0)


def test_upright_closed_hand_with_its_thumb_up_is_not_the_sign():
    # Fingers closed and the thumb up, held still: only the hand's axis, upright, tells it from a
    # thumbs-up; without that test it pauses.
    upright = upright_closed_hand()
    out, sign = _play([(OPEN, 0.5), (upright, 2.0)])
    assert np.all(out[:, 0] == 0) and sign[2] == 0
    out, _ = _play([(OPEN, 0.5), (upright, 2.0)], config=HandSign(axis_from_up_min_deg=0.0))
    assert out[-1, 0] == 1
    # A thumbs-up tilted 30 deg up (the forearm raised) is still the sign.
    tilt = np.radians(30.0)
    c, s_ = np.cos(tilt), np.sin(tilt)
    axis = THUMBS_UP[9] - THUMBS_UP[0]
    axis[2] = 0.0
    axis /= np.linalg.norm(axis)
    n = np.cross(axis, [0.0, 0.0, 1.0])  # turn about the horizontal line across the fist
    K = np.array([[0, -n[2], n[1]], [n[2], 0, -n[0]], [-n[1], n[0], 0]])
    R = np.eye(3) + s_ * K + (1 - c) * K @ K
    tilted = (THUMBS_UP - THUMBS_UP[0]) @ R.T
    assert 50.0 < axis_from_up_deg(tilted) < 70.0 and thumb_elevation_deg(tilted) < 35.0
    out, _ = _play([(OPEN, 0.5), (tilted, 1.0)])
    assert out[-1, 0] == 1


def test_sign_toggles_the_panels_pause():
    out, _ = _play([(OPEN, 0.5), (THUMBS_UP, 1.0)], panel_pause=1.0)
    assert out[0, 0] == 1 and out[-1, 0] == 0  # paused by the panel, resumed by the sign


@pytest.fixture(scope="module")
def population():
    return generate_population(GeneratorConfig(), n_users=8, seed=0)


def _population_toggles(population, config):
    toggles = 0
    for clip in population:
        state, step = initial_state(), int(round(clip.fps / 10))
        for i in range(0, clip.num_frames, step):  # at the policy rate, as in the diagram
            state = sign_step(state, clip.keypoints[i], i / clip.fps, config)
        toggles += int(state[4])
    return toggles


def test_no_gesture_of_the_population_makes_the_sign(population):
    assert _population_toggles(population, HandSign()) == 0
    # The thumb is what sets the sign apart: a closed hand held still, whatever its thumb, is among
    # the people's gestures.
    assert _population_toggles(population, HandSign(thumb_up_within_deg=180.0, thumb_hysteresis_deg=0.0)) > 10


@pytest.mark.parametrize("key, value, fragment", [
    ("fist_below", 2.0, "fist_below < open_above"), ("hold_s", 0.0, "hold_s"),
    ("thumb_up_within_deg", 80.0, "sum < 90"), ("axis_from_up_min_deg", 180.0, "axis_from_up_min_deg")])
def test_scenario_checks_the_sign(tmp_path, key, value, fragment):
    from rtcohand_drake.scenario import ScenarioError, load_scenario

    path = tmp_path / "s.yaml"
    path.write_text(f"hand_sign: {{{key}: {value}}}\n")
    with pytest.raises(ScenarioError, match=fragment):
        load_scenario(path)
