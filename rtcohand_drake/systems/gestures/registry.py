"""The gesture sources by name: what `python -m rtcohand_drake.run --gesture-source NAME` builds.

Each entry names a factory `from_options(options, scenario) -> GestureSetup`,
where `options` carries the run command's flags (`seed`, `user`,
`population_seed`, `gesture_file`, `clip`, ...; see `rtcohand_drake.run`).
A new source is one module with such a factory and one row here. Factories
are imported only when their source is chosen, so a source with heavy
dependencies (a camera stack) costs nothing to the others.
"""

from __future__ import annotations

import dataclasses as dc
import importlib
from typing import Callable


@dc.dataclass(frozen=True)
class GestureSourceEntry:
    module: str
    summary: str
    factory: str = "from_options"
    uses_policy: bool = True  # False: the source outputs `twist_request` itself (no policy, no filter)
    # Whose hand it plays: "simulated", "real" (a tracker), or "file" (that of its --gesture-file:
    # real unless the file is a generated population).
    hands: str = "simulated"


@dc.dataclass
class GestureSetup:
    """A built source, the context it brings, and where its stream ends."""

    source: object  # a LeafSystem with the gesture-source ports (or `twist_request` without a policy)
    # The user's own labelled clips as policy context when the run gives no --context-file:
    # a callable returning [(features (T, 36), labels (T, 6)), ...], given path_shape=True the features
    # followed by the hand's path and shape (`to_policy_clip`); None when the source has none.
    default_context: Callable[[], list] | None = None
    # Seconds, for a finite stream (the run ends there by default); inf for a live stream (the run
    # goes on until Ctrl-C); None: the run ends when the task is done (scenario.stop_when_done).
    end_time: float | None = None


GESTURE_SOURCES: dict[str, GestureSourceEntry] = {
    "synthetic": GestureSourceEntry("rtcohand_drake.systems.gestures.simulated_person",
                                    "the built-in simulated person, in closed loop (--user, --population-seed)"),
    "replay": GestureSourceEntry("rtcohand_drake.systems.gestures.replay",
                                 "clips of a dataset file, back to back (--gesture-file, --clip)", hands="file"),
    "recorded": GestureSourceEntry("rtcohand_drake.systems.gestures.recorded_person",
                                   "the simulated person's decisions with a recorded person's own held-out "
                                   "gestures, in closed loop (--gesture-file, --clip PERSON)", hands="file"),
    "camera": GestureSourceEntry("rtcohand_drake.systems.gestures.camera", "a live hand tracker", hands="real"),
    "scripted": GestureSourceEntry("rtcohand_drake.systems.scripted_twist",
                                   "the scenario's scripted_motion, straight to the supervisor (no policy)",
                                   uses_policy=False),
    "joystick": GestureSourceEntry("rtcohand_drake.systems.joystick",
                                   "the built-in simulated person at the arm maker's joystick (no policy; "
                                   "--user, --population-seed)", uses_policy=False),
}


def make_gesture_source(name: str, options, scenario) -> GestureSetup:
    """Builds the source registered as `name` (a KeyError names an unregistered one)."""
    entry = GESTURE_SOURCES[name]
    factory = getattr(importlib.import_module(entry.module), entry.factory)
    return factory(options, scenario)


def reads_real_hands(name: str, gesture_file=None) -> bool:
    """Whether the source `name` plays a real hand's skeleton: a tracker, or a --gesture-file that is
    not a generated population (`data.dataset.is_generated`). Such a run reads the scenario's
    `policy.real_hand_model`."""
    hands = GESTURE_SOURCES[name].hands
    if hands == "file":
        from rtcohand_drake.data.dataset import is_generated

        return gesture_file is not None and not is_generated(gesture_file)
    return hands == "real"


def policy_model_name(policy, real_hands: bool) -> str:
    """The policy file a run reads without --model: `policy.real_hand_model` for a real hand (when
    set), else `policy.model` (`policy` is a scenario's policy settings)."""
    return policy.real_hand_model if real_hands and policy.real_hand_model else policy.model
