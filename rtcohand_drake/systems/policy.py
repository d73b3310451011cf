"""`CchpPolicy`: the exported CCHP TorchScript policy as a Drake LeafSystem.

The system loads the TorchScript file (docs/interfaces.md, the exported policy) once and keeps the
module as an attribute; the recurrent state is numpy discrete state, so the
context clones cleanly. The user's context clips are encoded once, at
construction (keys, values, and the latent prior q(z|C) = N(z_mu, z_sigma)).

Every policy period (1 / rate_hz) it runs one `step` on the newest gesture
features, feeding back the module's own previous mean. When `resume_count`
changes (the operator resumed after a pause) the recurrent state is cleared and
a new z is drawn from q(z|C); the draw is deterministic given (seed,
resume_count), so a run is reproducible.

What it outputs as the twist is, with w = `correction_weight`,

    policy_mean = r(t) + w * (mean(t) - r(t)),   r(t) = attention(t) . values

r(t) is the context read: the user's own labelled twists, weighted by how alike
the gestures are. For a model with `read_skip` (the shipped one), mean - r is
the correction of the decoder f_y, which was learned on other people and pulls
a gesture toward what it means to them; w = 1 is the module's mean itself (the
paper's CCHP), w = 0 the read alone (`policy.correction_weight` in the
scenario; docs/policy.md has what each does in the closed-loop task). The module
is always fed its own mean, as in training, whatever w is.

A step whose features jump far beyond the person's own motion (the hand re-found elsewhere, a
replay moving on to its next clip) reads as no motion and starts the path-and-shape path afresh,
as does a hand seen again after a loss of two periods or more (the jump guard,
`learning.rest_release`). The rest release (`policy.rest_release` in the scenario) then scales that
output by a gate fitted to the person's own clips when the box is built: once the hand has been
still for a few periods, the command lets go of the gesture the policy just saw, whatever its
memory still holds; the period the hand moves again, the gate is open. It only ever scales the
command down, and the module is still fed its own mean.

Where the policy file asks for it (its `command_hold` attribute; the shipped files ask for none) and the
scenario allows it (`policy.command_hold`), the command hold follows the release: once the output
has pointed along one command for a few periods, part of that command is held at its full size
until the output no longer points along it (`learning.command_hold`); it starts afresh on a resume.

Input ports
  gesture_features (36) hand-part velocities, user frame (zeros when the hand is lost)
  resume_count     (1)  optional; z is resampled when it changes
  keypoints        (63) only for a policy file that reads the hand's path and shape
                        (`feature_dim` = 36 + PATH_SHAPE_DIM, `learning.path_shape_policy`): the
                        source's skeleton (NaN when lost), turned into that input by a
                        `hand_features.PathShapeStream` whose memory is discrete state; the
                        context pieces must then carry the same features (`to_policy_clip(path_shape=True)`),
                        or the 36 alone for a person the file's fast-turn gate reads with the CCHP
                        alone (`path_shape_policy.turned_away_by_fast_turns`: the same read, without
                        building the path and shape); the port is left unread for a person the file
                        reads with the CCHP alone (its blend A = 0 once the context is encoded)
Output ports
  policy_mean      (6)  predicted twist [vx vy vz wx wy wz], m/s and rad/s, user frame (see above)
  policy_std       (6)
  attention        (K)  attention weights over the K context steps (mean over heads), computed
                        from the step's query only when the port is evaluated, so a period
                        costs the same whatever the number of context steps
  read_variance    (1)  the read's predictive variance factor v = 1 + phi^T A phi (>= 1): near 1 for a
                        gesture like the context's, larger for one unlike all of them (the
                        supervisor slows down for it); 1 for a model without the Bayesian linear read
"""

# No `from __future__ import annotations`: Drake's yaml_load_typed reads the real field types.
import dataclasses as dc
import os

import numpy as np
from pydrake.systems.framework import LeafSystem

from rtcohand_drake.data.hand_features import PATH_SHAPE_DIM, PathShapeStream
from rtcohand_drake.data.sampling import pack_context
from rtcohand_drake.errors import InputError
from rtcohand_drake.learning.policy_file import load_policy
from rtcohand_drake.learning.command_hold import CommandHold, fit_hold, hold_settings
from rtcohand_drake.learning.rest_release import LOST_STEPS, fit_rest_release
from rtcohand_drake.interfaces import (ATTENTION, FEATURE_DIM, GESTURE_FEATURES, KEYPOINTS, KEYPOINTS_DIM, POLICY_MEAN,
                                       POLICY_STD, READ_VARIANCE, RESUME_COUNT, SCALAR_DIM)


@dc.dataclass
class Policy:
    """The CCHP policy system."""

    # Policy update rate (Hz); the paper's deployment runs at 10 Hz.
    rate_hz: float = 10.0
    # Exported TorchScript policy: a path, or a file name inside models/. The shipped file reads every
    # source: the CCHP (models/cchp_default.pt) and, for a person whom the CCHP does not read and whose
    # hand moves unlike the simulated ones, a kernel read of the hand's path and shape fitted to their
    # own clips (rtcohand_drake.learning.path_shape_policy; docs/policy.md).
    model: str = "cchp_path_shape.pt"
    # A policy file for a real hand's skeleton, used in place of `model` when the run's gesture source
    # plays a real hand (the camera; replay and recorded people of a file that is not a generated
    # population), and by the recorder's and context_reading's check of such a person's clips
    # (rtcohand_drake.systems.gestures.registry.reads_real_hands). Empty (the default): `model` for
    # every source. `--model` overrides both.
    real_hand_model: str = ""
    # The twist output is r + w (mean - r), r the context read (attention . the user's own
    # labelled twists): 1 = the module's mean (the paper's CCHP), 0 = the read alone
    # (rtcohand_drake.systems.policy).
    correction_weight: float = 1.0
    # Let go of the command once the hand rests (the rest release, rtcohand_drake.learning.rest_release);
    # false: the output is the policy's own.
    rest_release: bool = True
    # The output twist is multiplied by this (>= 1): a read that gives only part of each gesture's
    # command (recorded people in the closed loop: docs/real_people.md, section 8) moves the part
    # faster. 1 = the policy's own output. The supervisor's limits apply as always.
    output_gain: float = 1.0
    # Hold a command the output keeps pointing along, where the policy file asks for it (its
    # `command_hold` attribute; the shipped files ask for none: rtcohand_drake.learning.command_hold);
    # false: never.
    command_hold: bool = True


def blended_output(mean, read, correction_weight: float) -> np.ndarray:
    """r + w (mean - r), `read` = attention . values: (6,), (1, 6), or (6, 6) with head d for dimension d."""
    mean = np.asarray(mean, float)
    if correction_weight == 1.0:
        return mean
    r = np.asarray(read, float)
    r = np.diagonal(r) if r.ndim == 2 and r.shape[0] == 6 else r.reshape(-1)
    return r + correction_weight * (mean - r)


class CchpPolicy(LeafSystem):
    def __init__(self, model_path, context_pieces, rate_hz: float = 10.0, seed: int = 0,
                 correction_weight: float = 1.0, rest_release: bool = True, output_gain: float = 1.0,
                 command_hold: bool = True, label_lag_s: float = 0.0):
        """`model_path`: an exported policy file, or a module already loaded by `load_policy`;
        `rest_release`: gate the output by the person's rest release (module docstring);
        `output_gain`: the output twist multiplied by it (scenario `policy.output_gain`);
        `command_hold`: hold a command the output keeps pointing along, where the file asks for it
        (`learning.command_hold`); `label_lag_s`: how late the context's labels follow the gesture (a
        recorder session's, `data.dataset.label_lag_s`), which the rest release is fitted for."""
        super().__init__()
        if not (np.isfinite(correction_weight) and 0.0 <= correction_weight <= 1.0):
            raise ValueError(f"correction_weight must be in [0, 1], got {correction_weight}")
        if not (np.isfinite(output_gain) and 1.0 <= output_gain <= 5.0):
            raise ValueError(f"output_gain must be in [1, 5], got {output_gain}")
        self.correction_weight = float(correction_weight)
        self.output_gain = float(output_gain)
        import torch

        torch.set_num_threads(1)  # one cheap step per period; do not compete with the simulator
        self._torch = torch
        if isinstance(model_path, (str, os.PathLike)):
            self.module, self.model_path = load_policy(model_path), str(model_path)
        else:  # an already loaded policy module
            self.module, self.model_path = model_path, getattr(model_path, "source_path", "")
        self._has_variance = hasattr(self.module, "step_with_variance")
        # `step_read` (policy files exported with it) skips the pass over the context that only the
        # attention needs; its query gives the attention on demand (`attention_of`).
        self._has_read = hasattr(self.module, "step_read") and hasattr(self.module, "attention_of")
        self.feature_dim = int(getattr(self.module, "feature_dim", FEATURE_DIM))
        widths = {np.shape(x)[1] for x, _ in context_pieces if np.ndim(x) == 2}
        # A file that reads the path and shape takes the 36 features alone from a person its fast-turn gate
        # reads with the CCHP alone (learning.path_shape_policy.turned_away_by_fast_turns): the same read.
        narrow = self.feature_dim > FEATURE_DIM and widths == {FEATURE_DIM}
        mismatch = InputError(
            f"{self.model_path or 'policy'}: reads {self.feature_dim} features per step, the context pieces have "
            f"{sorted(widths)}" + (" (a policy that reads the hand's path and shape needs context clips loaded "
                                   "with it: to_policy_clip(path_shape=True))" if self.feature_dim > FEATURE_DIM else ""))
        if widths and widths != {self.feature_dim} and not narrow:
            raise mismatch
        x_c, y_c, mask = pack_context(context_pieces)
        if narrow:
            from rtcohand_drake.learning.path_shape_policy import turned_away_by_fast_turns

            if not turned_away_by_fast_turns(self.module, x_c, mask):
                raise mismatch
        # The jump guard is always on; the gate as asked.
        self.release = fit_rest_release(context_pieces, int(round(float(label_lag_s) * rate_hz)))
        self.release.on = self.release.on and bool(rest_release)
        self.hold = fit_hold(hold_settings(self.module), context_pieces) if command_hold else None
        with torch.no_grad():
            keys, values, z_mu, z_sigma = self.module.encode_context(
                torch.from_numpy(x_c), torch.from_numpy(y_c), torch.from_numpy(mask))
        self._keys, self._values = keys.contiguous(), values.contiguous()
        # A file that reads the hand's path and shape, for a person it reads with the CCHP alone (A = 0):
        # the box keeps its keypoints port, but neither reads it nor follows the path (the file pads the
        # 36 features with zeros, which A = 0 never reads).
        # (Only a path-and-shape file's own `blend_choice` gives its A: a file wrapped around one, such as
        # learning.ridge_blend_policy's, gives its own blend there, so the box reads the skeleton for it.)
        self._path_shape_read = self.feature_dim > FEATURE_DIM and not (
            hasattr(self.module, "kernel_blend") and hasattr(self.module, "blend_choice")
            and float(self.module.blend_choice(self._keys)[0]) == 0.0)
        self._values_np = self._values.numpy().astype(np.float64)
        self.z_mu, self.z_sigma = z_mu.numpy().astype(np.float64), z_sigma.numpy().astype(np.float64)
        self.context_steps = int(keys.shape[0])
        self._query_size = int(self.module.query_size) if self._has_read else self.context_steps
        self._seed = int(seed)
        self.period_s = 1.0 / rate_hz
        H, Dz = int(self.module.hidden_size), int(self.module.latent_dim)
        self._H, self._Dz = H, Dz
        # TorchScript optimises a function on its first two calls (8-14 ms each here);
        # do that now, not inside the first policy periods of a real-time run.
        for _ in range(3):
            self.step(np.zeros(self.feature_dim if self._path_shape_read else FEATURE_DIM), np.zeros(6),
                      np.zeros(H), np.zeros(H), self.z_mu)

        self._x = self.DeclareVectorInputPort(GESTURE_FEATURES, FEATURE_DIM)
        self._resume = self.DeclareVectorInputPort(RESUME_COUNT, SCALAR_DIM)
        self._h = self.DeclareDiscreteState(H)
        self._c = self.DeclareDiscreteState(H)
        self._y = self.DeclareDiscreteState(6)  # the module's own mean, fed back
        self._std = self.DeclareDiscreteState(np.zeros(6))
        self._z = self.DeclareDiscreteState(self.sample_z(0))
        self._resumes = self.DeclareDiscreteState(np.zeros(1))
        self._query = self.DeclareDiscreteState(self._query_size)  # the attention itself for older files
        self._variance = self.DeclareDiscreteState(np.ones(1))
        self._out = self.DeclareDiscreteState(6)  # the twist output (module docstring)
        self._shape = None  # declared last: the states above keep their indices whatever the file
        if self.feature_dim > FEATURE_DIM:
            if self.feature_dim != FEATURE_DIM + PATH_SHAPE_DIM:
                raise InputError(f"{self.model_path}: reads {self.feature_dim} features; this box gives 36 or "
                                 f"{FEATURE_DIM + PATH_SHAPE_DIM}")
            self._keypoints = self.DeclareVectorInputPort(KEYPOINTS, KEYPOINTS_DIM)
            self._stream = PathShapeStream(rate_hz)
            self._shape = self.DeclareDiscreteState(self._stream.state)
        self._still = self.DeclareDiscreteState(np.zeros(1))  # the rest release's still count
        self._lost = self.DeclareDiscreteState(np.zeros(1))  # periods the hand has been lost (the path's restart)
        self._held = self.DeclareDiscreteState(CommandHold.initial_state())  # the command hold's state
        self.DeclarePeriodicDiscreteUpdateEvent(self.period_s, 0.0, self._update)
        self.DeclareStateOutputPort(POLICY_MEAN, self._out)
        self.DeclareStateOutputPort(POLICY_STD, self._std)
        self.DeclareVectorOutputPort(ATTENTION, self.context_steps, self._calc_attention,
                                     prerequisites_of_calc={self.discrete_state_ticket(self._query)})
        self.DeclareStateOutputPort(READ_VARIANCE, self._variance)

    @classmethod
    def from_scenario(cls, model_path, context_pieces, policy: Policy, seed: int = 0,
                      label_lag_s: float = 0.0) -> "CchpPolicy":
        """The box with the scenario's `policy` settings (rate, correction weight, rest release, output gain,
        command hold); `label_lag_s` as for the constructor."""
        return cls(model_path, context_pieces, policy.rate_hz, seed=seed, correction_weight=policy.correction_weight,
                   rest_release=policy.rest_release, output_gain=policy.output_gain,
                   command_hold=policy.command_hold, label_lag_s=label_lag_s)

    def sample_z(self, resume_count: int) -> np.ndarray:
        """z ~ q(z|C), deterministic in (seed, resume_count)."""
        rng = np.random.default_rng([self._seed, int(resume_count)])
        return self.z_mu + self.z_sigma * rng.standard_normal(self._Dz)

    def step(self, x, y_prev, h, c, z):
        """One policy step in numpy: (mean, std, h, c, read, v, query). `read` is the context read
        attention . values ((heads, 6), m/s and rad/s); `query` gives the attention through
        `attention(query)` (for a policy file without `step_read`, it is the attention)."""
        torch = self._torch
        f32 = lambda a: torch.from_numpy(np.ascontiguousarray(a, dtype=np.float32))
        args = (f32(x), f32(y_prev), f32(h), f32(c), self._keys, self._values, f32(z))
        with torch.no_grad():
            if self._has_read:
                mean, std, h2, c2, read, v, query = self.module.step_read(*args)
                return mean.numpy(), std.numpy(), h2.numpy(), c2.numpy(), read.numpy(), float(v[0]), query.numpy()
            if self._has_variance:
                mean, std, h2, c2, attn, v = self.module.step_with_variance(*args)
                v = float(v[0])
            else:  # a policy file without the method: no variance to report
                (mean, std, h2, c2, attn), v = self.module.step(*args), 1.0
        attn = attn.numpy()
        read = np.atleast_2d(attn) @ self._values_np
        return mean.numpy(), std.numpy(), h2.numpy(), c2.numpy(), read, v, attn.mean(axis=0) if attn.ndim == 2 else attn

    def attention(self, query) -> np.ndarray:
        """The attention (K) over the context steps, mean over heads, of a step's query."""
        if not self._has_read:
            return np.asarray(query, float)
        torch = self._torch
        with torch.no_grad():
            attn = self.module.attention_of(torch.from_numpy(np.asarray(query, dtype=np.float32)), self._keys).numpy()
        return attn.mean(axis=0) if attn.ndim == 2 else attn

    def _calc_attention(self, context, output):
        output.SetFromVector(self.attention(context.get_discrete_state(self._query).get_value()))

    def _update(self, context, discrete_state):
        get = lambda i: context.get_discrete_state(i).get_value()
        h, c, y_prev, z = get(self._h), get(self._c), get(self._y), get(self._z)
        resumes_changed = False
        if self._resume.HasValue(context):
            resumes = float(self._resume.Eval(context)[0])
            if resumes != get(self._resumes)[0]:
                resumes_changed = True
                h, c, y_prev = np.zeros_like(h), np.zeros_like(c), np.zeros(6)
                z = self.sample_z(int(resumes))
                discrete_state.set_value(self._resumes, [resumes])
                discrete_state.set_value(self._z, z)
        x = np.asarray(self._x.Eval(context), float)
        x = np.where(np.isfinite(x), x, 0.0)  # a lost or corrupt frame reads as "no motion"
        jumped = self.release.is_jump(x)
        if jumped:  # the tracked hand jumped (learning.rest_release): no motion, and a fresh path
            x = np.zeros_like(x)
        if self._shape is not None and self._path_shape_read:  # a lost hand holds its last skeleton
            self._stream.state = np.array(get(self._shape))
            keypoints = self._keypoints.Eval(context)
            seen = bool(np.isfinite(keypoints).all())
            lost = float(get(self._lost)[0])
            if resumes_changed or jumped or (seen and lost >= LOST_STEPS):  # a fresh path (module docstring)
                self._stream.reset()
            discrete_state.set_value(self._lost, [0.0 if seen else lost + 1.0])
            shape, _ = self._stream.update(keypoints)
            discrete_state.set_value(self._shape, self._stream.state)
            x = np.concatenate([x, shape])
        still = 0.0 if resumes_changed else self.release.next_count(float(get(self._still)[0]), x[:FEATURE_DIM])
        discrete_state.set_value(self._still, [still])
        mean, std, h, c, read, v, query = self.step(x, y_prev, h, c, z)
        out = blended_output(mean, read, self.correction_weight) * self.release.gate(still)
        held = CommandHold.initial_state() if resumes_changed else np.array(get(self._held))
        if self.hold is not None and np.all(np.isfinite(out)):
            out, held = self.hold.step(held, out)
        out = out * self.output_gain
        if not (np.all(np.isfinite(out)) and np.all(np.isfinite(mean)) and np.all(np.isfinite(h))
                and np.all(np.isfinite(c))):
            mean, out, std = np.zeros(6), np.zeros(6), np.full(6, np.inf)  # never pass a NaN on: no motion
            v = np.inf
            h, c = np.zeros_like(h), np.zeros_like(c)
            held = CommandHold.initial_state()
        discrete_state.set_value(self._held, held)
        discrete_state.set_value(self._h, h)
        discrete_state.set_value(self._c, c)
        discrete_state.set_value(self._y, mean)
        discrete_state.set_value(self._out, out)
        discrete_state.set_value(self._std, std)
        discrete_state.set_value(self._variance, [v if np.isfinite(v) else np.inf])
        discrete_state.set_value(self._query, np.where(np.isfinite(query), query, 0.0))
