"""Which policy file a command reads without --model: the scenario's `policy.model`, one file for every
source (simulated people, the camera, replay and recorded people, the recorder's and context_reading's
check of a person's clips), unless `policy.real_hand_model` names another for a real hand's skeleton."""

import dataclasses
import pathlib
from types import SimpleNamespace

import h5py
import pytest

from rtcohand_drake.analysis import context_reading
from rtcohand_drake.data.dataset import is_generated, write_dataset
from rtcohand_drake.data.population import GeneratorConfig, generate_population
from rtcohand_drake.errors import run_cli
from rtcohand_drake.run import _resolve_model
from rtcohand_drake.scenario import load_scenario
from rtcohand_drake.systems.gestures.registry import GESTURE_SOURCES, policy_model_name, reads_real_hands

MODELS = pathlib.Path(__file__).resolve().parents[1] / "models"


@pytest.fixture(scope="module")
def files(tmp_path_factory):
    """A generated population file, and the same people written as a recording (no generator)."""
    folder = tmp_path_factory.mktemp("people")
    people = list(generate_population(GeneratorConfig(), n_users=1, seed=4))
    generated, recorded = folder / "generated.h5", folder / "recorded.h5"
    write_dataset(generated, people, generator="{}")
    write_dataset(recorded, people)
    return generated, recorded


def test_every_source_is_read_by_the_one_default_file_unless_a_file_for_real_hands_is_named(files):
    generated, recorded = files
    assert is_generated(generated) and not is_generated(recorded) and not is_generated(generated.parent / "none.h5")
    scenario = load_scenario("inspection")
    assert (scenario.policy.model, scenario.policy.real_hand_model) == ("cchp_path_shape.pt", "")
    real = {("synthetic", None): False, ("camera", None): True, ("replay", generated): False,
            ("replay", recorded): True, ("recorded", generated): False, ("recorded", recorded): True}
    for (source, gesture_file), is_real in real.items():
        assert reads_real_hands(source, gesture_file) == is_real, source
        args = SimpleNamespace(model=None, gesture_source=source, gesture_file=gesture_file)
        assert _resolve_model(args, scenario) == MODELS / "cchp_path_shape.pt", (source, gesture_file)
        assert _resolve_model(SimpleNamespace(model=pathlib.Path("mine.pt"), gesture_source=source,
                                              gesture_file=gesture_file), scenario) == pathlib.Path("mine.pt")
        named = dataclasses.replace(scenario, policy=dataclasses.replace(scenario.policy, model="cchp_default.pt",
                                                                         real_hand_model="cchp_path_shape.pt"))
        assert _resolve_model(args, named) == MODELS / ("cchp_path_shape.pt" if is_real else "cchp_default.pt")
    assert {n for n, e in GESTURE_SOURCES.items() if e.hands != "simulated"} == {"camera", "replay", "recorded"}
    # An empty real_hand_model: one file for every source.
    assert policy_model_name(SimpleNamespace(model="a.pt", real_hand_model=""), True) == "a.pt"


def test_context_reading_checks_every_persons_clips_with_the_one_default_file(files, capsys):
    for path in files:
        with h5py.File(path) as f:
            user = sorted(f["users"])[0]
        assert run_cli(context_reading.main, ["--context-file", str(path), "--context-user", user, "--folds", "2",
                                              "--no-progress"]) == 0
        printed = capsys.readouterr().out
        assert "policy cchp_path_shape.pt" in printed
        assert "read: the CCHP alone: the CCHP alone reads these clips at " in printed  # the palm turns slowly


def test_the_run_builds_the_path_and_shape_only_for_a_person_the_default_file_reads_with_them(files):
    """The run asks the context for the hand's path and shape only where the default file's fast-turn gate
    lets the kernel read in: a simulated person (the palm never turns fast) is read from the 36 features
    alone, which give the same read; a person whose palm turns fast brings the path and shape; a file of
    the 36 features alone never asks for them; a real hand's clips are read once, with them."""
    from rtcohand_drake.data.dataset import context_pieces
    from rtcohand_drake.learning.policy_file import load_policy
    from rtcohand_drake.run import _policy_context

    generated, _ = files
    with h5py.File(generated) as f:
        user = sorted(f["users"])[0]
    asked = []

    def load(wide, palm_turn=None):
        asked.append(wide)
        pieces, who = context_pieces(generated, user, 10.0, path_shape=wide)
        for x, _ in pieces if palm_turn is not None else ():
            x[:, 3:6] = palm_turn  # the palm turning at sqrt(3) x palm_turn rad/s in every step
        return pieces, who

    one_file = load_policy(MODELS / "cchp_path_shape.pt")
    pieces, who = _policy_context(one_file, load)
    assert asked == [False] and who == user and {x.shape[1] for x, _ in pieces} == {36}
    asked.clear()
    pieces, _ = _policy_context(one_file, lambda wide: load(wide, palm_turn=3.0))
    assert asked == [False, True] and {x.shape[1] for x, _ in pieces} == {int(one_file.feature_dim)} != {36}
    asked.clear()
    _policy_context(load_policy(MODELS / "cchp_default.pt"), load)
    assert asked == [False]
    # A real hand's clips (a recording, a tracker's source) are loaded once, with the path and shape.
    asked.clear()
    pieces, _ = _policy_context(one_file, load, real_hands=True)
    assert asked == [True] and {x.shape[1] for x, _ in pieces} == {int(one_file.feature_dim)}
