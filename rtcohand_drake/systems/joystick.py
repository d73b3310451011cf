"""The joystick baseline: a simulated operator driving the arm with the maker's gamepad semantics.

`--gesture-source joystick` replaces the gesture pipeline (source, policy,
filter) by a person at the arm maker's joystick, under the same safety layer.
The person is the built-in simulated person of the same user (`--user`,
`--population-seed`): the same perception delay and noise, the same plan
(lift, present, turn each face to the eye) and the same rhythm of decisions,
settling and rests. What changes is the hand: it holds sticks instead of
gesturing. The semantics modelled, from the paper's description of the Gen3
baseline (section "Controller (baseline)"): the controller moves or turns the
end effector at a factory-defined speed; it does not move and turn at the
same time, so the person toggles between a translation mode and a rotation
mode with a button; a stick carries one or two axes at a time. Here:

- `JoystickMapper` reads the person's intended twist (user frame). Each of
  its periods, the part the person wants most (translation or rotation, each
  measured against its own full speed) decides the mode; if that is not the
  current mode, the person presses the toggle and nothing moves for
  `toggle_dwell_s`. Then the (at most) `max_axes` largest axes of that part
  are pushed fully: each at +-`linear_speed_m_s` or +-`angular_speed_rad_s`
  (the fixed speed), while the wish on that axis exceeds `deadband` of the
  full speed; the other part waits for a later stroke.
- The person expects the part to follow at the joystick's speed (their
  strokes and their "let go before it arrives" are timed for it), and lets
  go of a stick in 0.1-0.2 s instead of bringing a hand back to rest.
- The fixed speeds default to 0.2 m/s and 0.5 rad/s, the maximum Cartesian
  speeds of a Gen3 gamepad teleoperation node for the Kortex driver
  (husarion/kortex_joystick_demo, parameters max_linear_vel and
  max_angular_vel); the toggle dwell of 0.6 s is a button press and the
  glance at the pad it takes.

`JoystickOperator` is the diagram of the two, with the policy-less source's
ports: input workpiece.pose (7); outputs twist_request (6) and
gesture_status (2) (always valid: a gamepad does not lose track of a hand).
The joystick mode (0 translation, 1 rotation) is also an output,
`joystick_mode` (1).
"""

# No `from __future__ import annotations`: Drake's yaml_load_typed reads the real field types.
import dataclasses as dc

import numpy as np
from pydrake.systems.framework import BasicVector, Diagram, DiagramBuilder, LeafSystem

from rtcohand_drake.interfaces import (GESTURE_STATUS, GESTURE_STATUS_DIM, INTENDED_TWIST, SCALAR_DIM, TWIST_DIM,
                                       TWIST_REQUEST, WORKPIECE_POSE)

JOYSTICK_MODE = "joystick_mode"
TRANSLATION, ROTATION = 0, 1


@dc.dataclass
class Joystick:
    """The gamepad's semantics (module docstring)."""

    linear_speed_m_s: float = 0.2
    angular_speed_rad_s: float = 0.5
    toggle_dwell_s: float = 0.6
    max_axes: int = 2
    deadband: float = 0.15
    period_s: float = 0.02


def joystick_twist(intended: np.ndarray, mode: int, config: Joystick) -> tuple[int, np.ndarray]:
    """(the mode the intent asks for, the twist the sticks give in that mode) for one intended twist."""
    intended = np.nan_to_num(np.asarray(intended, float))
    full = np.array([config.linear_speed_m_s] * 3 + [config.angular_speed_rad_s] * 3)
    share = np.abs(intended) / full
    wants = [share[:3].max(), share[3:].max()]
    if max(wants) <= config.deadband:
        return mode, np.zeros(6)
    wanted_mode = TRANSLATION if wants[0] >= wants[1] else ROTATION
    part = slice(0, 3) if wanted_mode == TRANSLATION else slice(3, 6)
    twist = np.zeros(6)
    axes = np.argsort(-share[part])[: config.max_axes]
    for axis in axes:
        if share[part][axis] > config.deadband:
            k = part.start + axis
            twist[k] = np.sign(intended[k]) * full[k]
    return wanted_mode, twist


class JoystickMapper(LeafSystem):
    def __init__(self, config: Joystick):
        super().__init__()
        self._cfg = config
        self._intent = self.DeclareVectorInputPort(INTENDED_TWIST, TWIST_DIM)
        # [mode, toggle done at (s), twist (6)]
        self._state = self.DeclareDiscreteState(np.concatenate([[TRANSLATION, -np.inf], np.zeros(6)]))
        self.DeclarePeriodicDiscreteUpdateEvent(config.period_s, 0.0, self._update)
        self.DeclareVectorOutputPort(TWIST_REQUEST, TWIST_DIM, self._calc_twist, prerequisites_of_calc={self.xd_ticket()})
        self.DeclareVectorOutputPort(GESTURE_STATUS, GESTURE_STATUS_DIM, self._calc_status,
                                     prerequisites_of_calc={self.time_ticket()})
        self.DeclareVectorOutputPort(JOYSTICK_MODE, SCALAR_DIM, self._calc_mode, prerequisites_of_calc={self.xd_ticket()})

    def _update(self, context, discrete_state):
        t = context.get_time()
        mode, toggled_at, *_ = context.get_discrete_state(self._state).get_value()
        wanted, twist = joystick_twist(self._intent.Eval(context), int(mode), self._cfg)
        if wanted != int(mode):  # press the toggle: nothing moves until it has taken
            mode, toggled_at = wanted, t + self._cfg.toggle_dwell_s
        if t < toggled_at:
            twist = np.zeros(6)
        discrete_state.set_value(self._state, np.concatenate([[mode, toggled_at], twist]))

    def _calc_twist(self, context, output: BasicVector):
        output.SetFromVector(context.get_discrete_state(self._state).get_value()[2:])

    def _calc_status(self, context, output: BasicVector):
        output.SetFromVector([1.0, context.get_time()])

    def _calc_mode(self, context, output: BasicVector):
        output.SetFromVector([context.get_discrete_state(self._state).get_value()[0]])


class JoystickOperator(Diagram):
    """The simulated person at the joystick (module docstring)."""

    def __init__(self, person, config: Joystick):
        super().__init__()
        builder = DiagramBuilder()
        person = builder.AddNamedSystem("person", person)
        mapper = builder.AddNamedSystem("joystick", JoystickMapper(config))
        builder.Connect(person.GetOutputPort(INTENDED_TWIST), mapper.GetInputPort(INTENDED_TWIST))
        builder.ExportInput(person.GetInputPort(WORKPIECE_POSE), WORKPIECE_POSE)
        for name in (TWIST_REQUEST, GESTURE_STATUS, JOYSTICK_MODE):
            builder.ExportOutput(mapper.GetOutputPort(name), name)
        builder.BuildInto(self)
        self.person = person


def joystick_person_config(config: Joystick):
    """The simulated person's habits at a joystick: strokes timed for its speed, quick release."""
    from rtcohand_drake.systems.gestures.simulated_person import PersonConfig

    return PersonConfig(expected_speed_m_s=config.linear_speed_m_s, expected_rate_rad_s=config.angular_speed_rad_s,
                        return_mode="out_of_view", out_of_view_s=(0.1, 0.2))


def from_options(options, scenario):
    """The `joystick` source: the built-in person of `options.user` / `options.population_seed` at a joystick."""
    from rtcohand_drake.data.population import DEFAULT_SEED
    from rtcohand_drake.systems.gestures.registry import GestureSetup
    from rtcohand_drake.systems.gestures.simulated_person import make_builtin_person

    config = Joystick()
    population = DEFAULT_SEED if options.population_seed is None else options.population_seed
    person, _ = make_builtin_person(scenario, seed=options.seed, user=options.user,
                                    config=joystick_person_config(config), population_seed=population)
    return GestureSetup(JoystickOperator(person, config))
