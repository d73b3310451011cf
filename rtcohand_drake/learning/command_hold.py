"""The command hold: a read that keeps pointing along one command is held at that command's size.

A read of a real hand points the right way through most of a gesture but at about half the
command's size (docs/real_people.md, "The command hold"): a kernel read of a
hand unlike every context step shrinks toward zero, and the least-squares blend that chose it
shrinks further. The person keeps gesturing until the part arrives, so a read that is right and
small makes the task slow. The hold lets the read decide once, and then keeps the decision:

    s(t)     = y(t) / sizes                   y the policy box's twist (after the rest release); sizes
                                              the person's command size on each axis (the largest
                                              label of their context clips; an axis of size 0 is
                                              never held)
    d(t)     = the axis and sign of s's largest component, |s|(t) its size
    a candidate d has |s| >= high for steps_on steps in a row: it becomes the held command (or
    replaces the one held);
    the held command ends once the output along it, sign(d) s_d(t), is under low for steps_off
    steps in a row (the hand rests and the rest release has let go; or the read has faded, or
    turned to another command);
    while a command d is held:  y'(t) = share x sign(d) sizes[d] e_d + (1 - share) y(t);
    otherwise                   y'(t) = y(t).

The hold only ever adds a command the read itself has pointed along for `steps_on` steps; the rest
release still zeroes the read at rest, and the hold ends `steps_off` steps after. A policy file
asks for it with its attribute `command_hold` = [high, steps_on, low, steps_off, share]
(`learning.path_shape_policy --hold`); the policy box applies it (scenario `policy.command_hold`,
default true) and so do the offline reads of the box (`benchmarks/back_to_back_read.py`).
Everything it remembers is `STATE_SIZE` numbers (`state`).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Sequence

import numpy as np

STATE_SIZE = 6  # [held axis (-1: none), held sign, candidate axis (-1: none), candidate sign, its steps, steps low]


@dataclass
class CommandHold:
    """A person's command hold (module docstring)."""

    sizes: np.ndarray = field(default_factory=lambda: np.zeros(6))
    high: float = 0.3
    steps_on: int = 3
    low: float = 0.1
    steps_off: int = 2
    share: float = 0.5

    def __post_init__(self):
        self.sizes = np.asarray(self.sizes, np.float64).reshape(6)
        if not (0.0 <= self.low < self.high and self.steps_on >= 1 and self.steps_off >= 1
                and 0.0 <= self.share <= 1.0):
            raise ValueError(f"command hold needs 0 <= low < high, steps >= 1 and share in [0, 1]; got high "
                             f"{self.high}, steps_on {self.steps_on}, low {self.low}, steps_off {self.steps_off}, "
                             f"share {self.share}")

    @classmethod
    def from_settings(cls, sizes, settings: Sequence[float]) -> "CommandHold":
        """The hold of [high, steps_on, low, steps_off, share] (a policy file's `command_hold`)."""
        high, steps_on, low, steps_off, share = (float(v) for v in settings)
        return cls(sizes, high, int(steps_on), low, int(steps_off), share)

    @staticmethod
    def initial_state() -> np.ndarray:
        return np.array([-1.0, 0.0, -1.0, 0.0, 0.0, 0.0])

    def step(self, state: np.ndarray, y: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(the held twist (6,), the next state) from a state and the box's twist y (6,)."""
        held, held_sign, cand, cand_sign, count, off = (float(v) for v in state)
        y = np.asarray(y, np.float64)
        known = self.sizes > 0
        s = np.where(known, y / np.where(known, self.sizes, 1.0), 0.0)
        axis = int(np.abs(s).argmax())
        size, sign = abs(float(s[axis])), float(np.sign(s[axis]))
        if size >= self.high and known[axis]:
            count = count + 1.0 if (axis, sign) == (cand, cand_sign) else 1.0
            cand, cand_sign = float(axis), sign
        else:
            cand, cand_sign, count = -1.0, 0.0, 0.0
        if held >= 0:  # the read still supports the held command while its output along it is >= low
            along = held_sign * float(s[int(held)])
            off = off + 1.0 if along < self.low else 0.0
            if off >= self.steps_off:
                held, held_sign, off = -1.0, 0.0, 0.0
        if cand >= 0 and count >= self.steps_on and (cand, cand_sign) != (held, held_sign):
            held, held_sign, off = cand, cand_sign, 0.0
        out = y.copy()
        if held >= 0:
            command = np.zeros(6)
            command[int(held)] = held_sign * self.sizes[int(held)]
            out = self.share * command + (1.0 - self.share) * y
        return out, np.array([held, held_sign, cand, cand_sign, count, off])

    def apply(self, outputs: np.ndarray) -> np.ndarray:
        """(T, 6) the held twists of a stream of the box's twists (T, 6), from the initial state."""
        state, out = self.initial_state(), []
        for y in np.asarray(outputs, np.float64):
            held, state = self.step(state, y)
            out.append(held)
        return np.array(out).reshape(-1, 6)


def hold_settings(module) -> list[float] | None:
    """The policy file's `command_hold` attribute ([high, steps_on, low, steps_off, share]), or None."""
    settings = getattr(module, "command_hold", None)
    if settings is None:
        return None
    settings = [float(v) for v in settings]
    return settings if len(settings) == 5 and settings[4] > 0 else None


def fit_hold(settings: Sequence[float] | None, pieces) -> CommandHold | None:
    """A person's hold from the file's settings and their labelled context pieces [(features, labels)];
    None without settings or labels."""
    if settings is None:
        return None
    labels = [np.nan_to_num(np.asarray(y, np.float64)).reshape(-1, 6) for _, y in pieces if y is not None]
    if not labels:
        return None
    return CommandHold.from_settings(np.abs(np.concatenate(labels)).max(0), settings)
