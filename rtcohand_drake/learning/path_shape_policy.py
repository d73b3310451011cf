"""A policy file that adds a kernel read of the hand's path and shape to an exported CCHP policy.

    python -m rtcohand_drake.learning.path_shape_policy --policy models/cchp_default.pt --out FILE.pt
        [--blend A] [--bandwidth S] [--lambda L] [--folds F] [--rows R] [--anchors N] [--min-gain G]
        [--min-cchp-error E] [--min-blend B] [--min-fast-turns F]
        [--commit SHARE LOW HIGH] [--match SHARE W TAU] [--hold HIGH STEPS_ON LOW STEPS_OFF SHARE]
        [--encoder ENCODER.pt]

The shipped policy file, `models/cchp_path_shape.pt` (the scenario's `policy.model`, for every
source), is this file built over the shipped CCHP, `models/cchp_default.pt`, with the defaults below.

The 36 hand-part velocities carry the hand's motion, not the posture it is made
in nor the path it took: a one-finger gesture and the same gesture of the whole
hand move alike, and a recorded person's 2-4 examples of each gesture do not
tell them apart by motion alone (docs/real_people.md). The file this writes
reads `feature_dim` = 36 + PATH_SHAPE_DIM features: the paper's 36 first, then
the hand's path and shape (`rtcohand_drake.data.hand_features.PathShapeStream`).
It keeps the exported CCHP policy whole, as a submodule fed the first 36, and
adds a Gaussian-kernel ridge read of the rest over the person's context:

    encode_context:  s_i = the context steps' path-and-shape features, standardised by their
                     own mean and spread; the anchors: every step of a context of at most N =
                     `--anchors` steps, else N steps spread evenly over it; over the anchors,
                     G_ij = exp(-|s_i - s_j|^2 / (2 b^2)), b = `--bandwidth` x the median distance
                     between them; M = (G + lambda I)^-1; W = M Y (Y the anchors' labels)
    step:            k_i = exp(-|s(t) - s_i|^2 / (2 b^2)); r_k = k . W = (k M) . values
                     mean = A r_k + (1 - A) mean_CCHP,  read = A r_k + (1 - A) read_CCHP

A is `--blend`, or with `--folds F` > 0 (the shipped file: 4) it is chosen for each person when the
context is encoded: the least-squares blend of the two reads over the person's own clips, each clip
read with the other folds' clips as context (`_cross_validated_blend`). With `--min-gain G` that
blend is used only for a person whose clips it reads with at least G less squared error than the
CCHP alone (`--min-gain off`, the shipped file: whatever it gains); for anyone else A = 0
(`blend_choice` gives A, the fitted A and that share). With `--min-cchp-error E` (the shipped file:
0.5) it is used only for a person whom the CCHP alone reads with at least E of zero twist's squared
error over their clips, and with `--min-blend B` (the shipped file: 0, any A) only where the fitted A
is at least B; anyone else gets the CCHP's own step, exactly. The
kernel read suits recorded people, whose few strokes differ in posture and path; the CCHP suits
sustained motions and the simulated people it was trained on.

With attention = A k M + (1 - A) attention_CCHP over the K context steps (the CCHP's `values`, which
a CCHP with `label_lead` shifts that many steps on, are returned as they are; the kernel read reads
the labels unshifted, so `read` is attention . values only up to that shift), and the box's
`correction_weight` still weighs the CCHP decoder's correction. `std` and the read variance
are the CCHP's. The CCHP is fed its own mean, carried in the last 6 entries of h (the caller's
`y_prev`, the blended mean, is not used). No training: the read is fitted by one linear solve,
from the person's own clips, when the context is encoded.

With `--commit SHARE LOW HIGH` (the shipped file: 0.5 0.2 0.6) SHARE of r_k is replaced by its dominant
command (`_committed`). With `--match SHARE W TAU` (the shipped file: 0.25 50 0.05) SHARE of that is
replaced by the stroke matched against each context clip with a time warp (`_match`): the frames (the
shape about the centre now, the centre's velocity over 0.4 s weighted W) of the stream's recent steps
matched to each clip from its first step, the clips' labels at their best matches weighted by
exp(-(mean cost - the best) / TAU). Its state rides in h and c after the CCHP's, with room for
MATCH_MAX_STEPS context steps; A is chosen on the committed kernel read without it.

With `--hold HIGH STEPS_ON LOW STEPS_OFF SHARE` (SHARE 0, the default and the shipped file's: none;
0.3 3 0.1 2 0.5 was tried and not shipped) the file asks the policy box to hold a command its output
keeps pointing along (`learning.command_hold`): the file's attribute `command_hold` carries the five
numbers; the file's own steps are unchanged.

With `--encoder` (a `learning.hand_encoder` file, learned across people), s_i and s(t) are the
encoder's embedding of the path and shape instead of the features themselves; the rest is unchanged.

Keys (K, D_in + ceil(own / K)): one block whose memory holds the CCHP's keys (K, D_in), then the
kernel read's part (`_own`), each piece row-major so that a step reads it as a view, without a copy:
over the a = min(K, N) anchors, M (a, a), s (a, PATH_SHAPE_DIM or the embedding's width), W (a, 6),
|s|^2 (a) and each anchor's step in the context (a); then the extras (the standardisation's mean and
spread, b and A, [the command sizes], [the match frames' mean, spread and fit], A as fitted and its
gain); then, with the match, each context step's standardised frame (66), its weighted square sum,
label (6), position in its clip and clip (K rows); last, the CCHP's own error over the person's clips, as
a share of zero twist's (`--min-cchp-error`). A step costs O(N) for the kernel read and O(K) for
the match (on while K <= MATCH_MAX_STEPS), and the keys O(K D_in + N^2). The settings were chosen on
recorded development people, the folds, the anchors and the gain also on development simulated
populations (docs/real_people.md, section 3; docs/policy.md).
"""

from __future__ import annotations

import argparse
import os
import pathlib
import sys
import warnings
from typing import List, Optional, Sequence, Tuple

import torch
from torch import nn

from rtcohand_drake.data.hand_features import FEATURE_DIM, PATH_SHAPE_DIM
from rtcohand_drake.errors import InputError, run_cli
from rtcohand_drake.learning.command_hold import CommandHold
from rtcohand_drake.learning.export import WrappedPolicySteps, blend_and_gain

# Chosen on the 10 recorded development people (docs/real_people.md, section 3).
DEFAULT_BLEND = 0.75
DEFAULT_BANDWIDTH = 0.5
DEFAULT_LAMBDA = 0.3
DEFAULT_CV_FOLDS = 4  # chosen on recorded development people and a development simulated population
DEFAULT_CV_ROWS = 12
# Chosen on the 6 recorded development training people, checked on the 4 validation ones
# (docs/real_people.md, section 6): half the read committed, full from 0.6 of a command, none below 0.2.
COMMIT_SHARE, COMMIT_LOW, COMMIT_HIGH = 0.5, 0.2, 0.6
DEFAULT_COMMIT_SHARE = COMMIT_SHARE  # the shipped file's
# The stroke matched against each context clip with a time warp (docs/real_people.md, section 6):
# its share of the kernel read, the weight of each of the centre's 3 velocity values against 1 for
# each of the 63 shape values, and tau of the softmin over clips. Chosen on the 6 recorded
# development training people, checked on the 4 validation ones.
MATCH_SHARE, MATCH_VELOCITY_WEIGHT, MATCH_TAU = 0.25, 50.0, 0.05
DEFAULT_MATCH_SHARE = MATCH_SHARE  # the shipped file's
MATCH_MAX_STEPS = 4096  # context steps the time warp's state has room for; a longer context is read without it
MATCH_FRAME_DIM = 66  # the hand's shape about its centre (63) and the centre's velocity over 0.4 s (3)
# A context step's frame, its weighted square sum, label, position in its clip and clip.
MATCH_COLUMNS = MATCH_FRAME_DIM + 1 + 6 + 2
# The context steps the kernel read is fitted on, at most: a longer context is read from this many of its
# steps, spread evenly over it, so that its solve, its keys and each step stay bounded (a 10,000-step
# context: keys of K x D_in + ANCHORS^2 + O(K) floats and a step over ANCHORS steps, not K^2 and K). 1,536:
# every recorded person (900-1,470 steps at 10 Hz) is read from all of their steps, and a step at 10,000
# context steps stays within the policy's budget (docs/policy.md); a simulated person (72 clips, about 3,000
# steps), whom the CCHP reads, gets the CCHP alone (DEFAULT_MIN_CCHP_ERROR).
DEFAULT_ANCHORS = 1536
# With `--min-gain G`, a person's kernel read is used only when the fitted blend removes at least G of the
# CCHP's squared error over their own clips. `--min-gain off` (GAIN_CONDITION_OFF): no gain condition; a
# person whom the other conditions admit gets the fitted blend whatever the sign of that gain, since a gain
# near zero on a person's own folds decides nothing. Off in the shipped file: at G = 0 one of the 30
# development person-maps was refused on a gain of -0.03 and read far worse without the blend; off, the
# 10 reported recorded people read as well or better on every map (docs/policy.md, "The per-person choice
# without its gain condition"). Gated at 0.2 (above every development simulated person's share) the file
# read two of three held-out populations worse than the CCHP alone (docs/policy.md).
GAIN_CONDITION_OFF = float("-inf")
DEFAULT_MIN_GAIN = GAIN_CONDITION_OFF
# The kernel read steps in only for a person whom the CCHP alone, cross-validated over their own clips, reads
# with at least this share of zero twist's squared error; anyone else gets the CCHP alone, exactly. Chosen on
# development people (docs/policy.md, "One file for every hand"): the CCHP's share was 0.08-0.18 for the 90
# simulated people of populations 0 and 1 (every 8th Own episode), 0.09-0.42 for two of our style families
# of population 7, and 0.65-1.36 for the 10 recorded development people on every map: 0.5 lies between.
DEFAULT_MIN_CCHP_ERROR = 0.5
# With `--min-blend B`, the kernel read is used only where the blend fitted on the person's clips gives it at least
# B (A): a small A is a small correction to a read that fits, its gain within the fit's noise. Off in the shipped
# file: B = 0.35 (every recorded development person with a kernel read had A of 0.48 or more; the simulated
# development people whom the CCHP reads with a share of 0.5 or more, 0.28 or less) gave one held-out simulated
# person a kernel read that read them worse, so it was not the one default either (docs/policy.md).
DEFAULT_MIN_BLEND = 0.0
# The kernel read is used only for a context whose palm turns faster than FAST_TURN_RAD_S in at least
# `--min-fast-turns` of its moving steps (steps with any of the 36 velocities nonzero): a hand that moves
# unlike the simulated hands the CCHP learned from. Chosen on development people (docs/policy.md, "One
# file for every hand: the kernel read for hands unlike the simulated ones"): simulated populations 0-10,
# four style families, one of people who make every motion the direct way and one of people who stroke,
# at most 0.3 % of such steps; one tracked as recorded hands were (`data.generate --recorded-tracking`) at
# most 3.1 %; the 10 recorded development people, 28-51 % on every map; the real camera footage, 21 %.
# 0.1 lies between (about the geometric mean of 3.1 % and 27.7 %).
FAST_TURN_RAD_S = 2.0
DEFAULT_MIN_FAST_TURNS = 0.1
# The command hold a file may ask the policy box for (learning.command_hold): [high, steps_on, low,
# steps_off, share]; share 0: none. HOLD_CHOSEN was chosen on the recorded development people's held-out
# gestures back to back through the run command; reported once it read every map better but drifted more
# in the closed loop, so the shipped file asks for none (docs/real_people.md, "The command hold").
NO_HOLD = (0.3, 3.0, 0.1, 2.0, 0.0)
HOLD_CHOSEN = (0.3, 3.0, 0.1, 2.0, 0.5)
DEFAULT_HOLD = NO_HOLD
MATCH_NONE = 1e18  # the cost of a match that cannot be made


class PathShapeKernelPolicy(WrappedPolicySteps):
    """The exported CCHP policy (first 36 features) blended with a kernel read of the path and shape."""

    def __init__(self, inner: torch.jit.ScriptModule, blend: float, bandwidth: float, lam: float,
                 folds: int = 0, rows: int = DEFAULT_CV_ROWS, encoder: Optional[torch.jit.ScriptModule] = None,
                 commit: Tuple[float, float, float] = (0.0, COMMIT_LOW, COMMIT_HIGH),
                 match: Tuple[float, float, float] = (0.0, MATCH_VELOCITY_WEIGHT, MATCH_TAU),
                 anchors: int = DEFAULT_ANCHORS, min_gain: float = 0.0,
                 hold: Tuple[float, float, float, float, float] = NO_HOLD, min_cchp_error: float = 0.0,
                 min_blend: float = 0.0, min_fast_turns: float = 0.0):
        super().__init__()
        if int(inner.feature_dim) != FEATURE_DIM or not hasattr(inner, "step_read"):
            raise InputError("the inner policy must read the 36 hand features and have step_read")
        if not (0.0 <= blend <= 1.0 and bandwidth > 0 and lam > 0 and folds >= 0 and rows >= 1):
            raise InputError(f"blend must be in [0, 1], bandwidth and lambda positive, folds >= 0 and rows >= 1; "
                             f"got {blend}, {bandwidth}, {lam}, {folds}, {rows}")
        if not (0.0 <= commit[0] <= 1.0 and 0.0 <= commit[1] < commit[2]):
            raise InputError(f"commit needs a share in [0, 1] and 0 <= low < high; got {tuple(commit)}")
        if not (0.0 <= match[0] <= 1.0 and match[1] >= 0 and match[2] > 0):
            raise InputError(f"match needs a share in [0, 1], a velocity weight >= 0 and tau > 0; got {tuple(match)}")
        try:  # the hold's own rule for its settings
            CommandHold.from_settings([0.0] * 6, hold)
        except (ValueError, TypeError) as err:
            raise InputError(f"hold {tuple(hold)}: {err}") from None
        # The command hold the box applies to this file's output (learning.command_hold); share 0: none.
        self.command_hold = [float(v) for v in hold]
        gain_ok = min_gain == GAIN_CONDITION_OFF or 0.0 <= min_gain < 1.0
        if anchors < 2 or not gain_ok or not 0.0 <= min_cchp_error < 10.0 or not 0.0 <= min_blend < 10.0:
            raise InputError(f"anchors must be at least 2, min_gain in [0, 1) or off, min_cchp_error in [0, 10) and "
                             f"min_blend in [0, 10); got {anchors}, {min_gain}, {min_cchp_error}, {min_blend}")
        # A person's kernel read is used only if, over their own clips, the fitted blend removes at least
        # this share of the CCHP's squared error (else A = 0: the CCHP alone).
        self.min_gain = float(min_gain)
        # ... and only if the CCHP alone, cross-validated over their own clips, reads them with at least this
        # share of the squared error of commanding zero twist: the kernel read steps in only for a person whom
        # the CCHP does not read (0: for anyone).
        self.min_cchp_error = float(min_cchp_error)
        # ... and only if the fitted A is at least this (0: any A; above 1: nobody).
        self.min_blend = float(min_blend)
        if not 0.0 <= min_fast_turns <= 1.0:
            raise InputError(f"min_fast_turns must be in [0, 1]; got {min_fast_turns}")
        # ... and only if the context's palm turns faster than fast_turn_rad_s in at least this share of its
        # moving steps (0: any context).
        self.min_fast_turns = float(min_fast_turns)
        self.fast_turn_rad_s = FAST_TURN_RAD_S
        self.inner = inner
        self.kernel_anchors = int(anchors)  # the context steps the kernel read is fitted on, at most
        self.inner_hidden = int(inner.hidden_size)
        self.inner_query_size = int(inner.query_size)
        # The kernel reads the path and shape as they are, or their embedding by a learned encoder
        # (learning.hand_encoder); shape_dim is the width of what it reads.
        self.encoder = nn.Identity() if encoder is None else encoder
        self.shape_dim = PATH_SHAPE_DIM if encoder is None else int(encoder.embed_dim)
        self.motion_feature_dim = FEATURE_DIM
        self.feature_dim = FEATURE_DIM + PATH_SHAPE_DIM
        # The time warp's state: each context step's best match cost (in h) and length (in c).
        self.match_share = float(match[0])
        self.match_velocity_weight = float(match[1])
        self.match_tau = float(match[2])
        self.match_max_steps = MATCH_MAX_STEPS if self.match_share > 0 else 0
        self.match_frame_dim = MATCH_FRAME_DIM
        self.match_columns = MATCH_COLUMNS
        self.match_none = MATCH_NONE
        # Each frame value's weight in a step's match cost: 1 for the 63 shape values, the velocity weight
        # for the centre's 3, normalised to sum to 1.
        weight = torch.ones(MATCH_FRAME_DIM)
        weight[63:] = self.match_velocity_weight
        self.match_weight = weight / weight.sum()
        self.hidden_size = self.inner_hidden + 6 + self.match_max_steps
        self.latent_dim = int(inner.latent_dim)
        self.motion_dim = 6
        self.attention_heads = 1
        self.query_size = self.inner_query_size + self.shape_dim
        self.kernel_blend = float(blend)  # A when not cross-validated, and for a context of one clip
        self.blend_folds = int(folds)  # 0: A fixed; else A chosen per context by this many folds of clips
        self.blend_rows = int(rows)  # the clips the cross-validation steps through, at most
        self.kernel_bandwidth = float(bandwidth)
        self.kernel_lambda = float(lam)
        # The read committed to one command: commit_share of it is the kernel read's dominant command at
        # full size once the read reaches commit_high of that size (none below commit_low); 0: off.
        self.commit_share = float(commit[0])
        self.commit_low = float(commit[1])
        self.commit_high = float(commit[2])
        # Extras: the standardisation's mean and spread, b, A, [the command sizes], [the match frame's
        # mean and spread, and 1 where the context fits the match's state].
        self.match_extras_at = 2 * self.shape_dim + 2 + (6 if self.commit_share > 0 else 0)
        # ... and last, A as fitted and the share of the CCHP's error over the person's clips that it removes.
        self.extra_size = self.match_extras_at + (2 * self.match_frame_dim + 1 if self.match_share > 0 else 0) + 2

    def _anchors(self, k: int) -> int:
        """a: the context steps the kernel read is fitted on, of K."""
        return min(k, self.kernel_anchors)

    def _own_size(self, k: int) -> int:
        """The floats of the kernel read's (and the match's) part of the keys, for K context steps."""
        a = self._anchors(k)
        return a * (a + self.shape_dim + 8) + self.extra_size + (k * self.match_columns if self.match_share > 0 else 0) + 1

    def _inner_keys(self, keys: torch.Tensor) -> torch.Tensor:
        """The CCHP's keys (K, D_in): the first K x D_in floats of the keys' memory (a view, no copy)."""
        k = keys.size(0)
        d_in = keys.size(1) - (self._own_size(k) + k - 1) // k
        return keys.reshape(-1)[:k * d_in].view(k, d_in)

    def _own(self, keys: torch.Tensor) -> torch.Tensor:
        """The kernel read's part of the keys' memory, flat (a view, no copy): M (a, a), s (a, shape_dim),
        W (a, 6), |s|^2 (a), each anchor's step in the context (a), the extras, the match's block, then the
        CCHP's own cross-validated error share (`blend_choice`)."""
        k = keys.size(0)
        start = keys.numel() - k * ((self._own_size(k) + k - 1) // k)
        return keys.reshape(-1)[start:start + self._own_size(k)]

    def _anchor_part(self, keys: torch.Tensor, column: int, width: int) -> torch.Tensor:
        """(a, width): the anchors' part that starts `column` columns into their rows, [M (a) | s
        (shape_dim) | W (6) | |s|^2 (1) | the anchor's step in the context (1)], each part row-major."""
        a = self._anchors(keys.size(0))
        return self._own(keys)[a * column:a * (column + width)].view(a, width)

    def _extras(self, keys: torch.Tensor) -> torch.Tensor:
        a = self._anchors(keys.size(0))
        at = a * (a + self.shape_dim + 8)
        return self._own(keys)[at:at + self.extra_size]

    def _match_block(self, keys: torch.Tensor) -> torch.Tensor:
        k = keys.size(0)
        a = self._anchors(k)
        at = a * (a + self.shape_dim + 8) + self.extra_size
        return self._own(keys)[at:at + k * self.match_columns].view(k, self.match_columns)

    def _match_frames(self, p: torch.Tensor) -> torch.Tensor:
        """(N, 66) match frames of path-and-shape rows (N, PATH_SHAPE_DIM): the shape about the centre
        now, and the centre's velocity over the first lag (0.4 s: the keypoints then about the centre now
        average to minus its displacement)."""
        n = p.size(0)
        return torch.cat([p[:, :63], -p[:, 63:126].reshape(n, 21, 3).mean(1) / 0.4], 1)

    @torch.jit.export
    def fast_turn_share(self, x_c: torch.Tensor, mask: torch.Tensor) -> torch.Tensor:
        """The share of the context's moving steps (any of the 36 velocities nonzero) in which the palm's
        frame turns faster than `fast_turn_rad_s` (0 for a context that never moves)."""
        x = torch.nan_to_num(x_c[:, :, :self.motion_feature_dim][mask.to(torch.bool)], 0.0, 0.0, 0.0)
        moving = x.abs().sum(1) > 0
        if int(moving.sum()) == 0:
            return torch.zeros((), dtype=torch.float64)
        turn = (x[moving][:, 3:6].to(torch.float64) ** 2).sum(1).sqrt()  # the palm (part 0): its angular velocity
        return (turn > self.fast_turn_rad_s).to(torch.float64).mean()

    @torch.jit.export
    def encode_context(self, x_c: torch.Tensor, y_c: torch.Tensor, mask: torch.Tensor
                       ) -> Tuple[torch.Tensor, torch.Tensor, torch.Tensor, torch.Tensor]:
        """The context of the paper's 36 features alone (a caller that knows nothing of the path and shape)
        is read by the CCHP alone, exactly: A = 0, and `step` takes 36 features then too. So is a context
        whose palm turns fast too seldom (`min_fast_turns`): for either, the kernel read is neither fitted
        nor cross-validated (its part of the keys is zeros, `blend_choice` gives A = 0 and -1 for what
        was not measured), and encoding costs about what the CCHP's own does."""
        return self._encode(x_c, y_c, mask, True)

    @torch.jit.export
    def encode_context_fitted(self, x_c: torch.Tensor, y_c: torch.Tensor, mask: torch.Tensor
                              ) -> Tuple[torch.Tensor, torch.Tensor, torch.Tensor, torch.Tensor]:
        """`encode_context` with the kernel read fitted and cross-validated whatever the fast-turn gate
        says (A used still obeys it; the same read): for the reading check and measurements of the
        kernel read itself."""
        return self._encode(x_c, y_c, mask, False)

    def _encode(self, x_c: torch.Tensor, y_c: torch.Tensor, mask: torch.Tensor, may_skip: bool
                ) -> Tuple[torch.Tensor, torch.Tensor, torch.Tensor, torch.Tensor]:
        if x_c.dim() != 3 or x_c.size(2) not in (self.motion_feature_dim, self.feature_dim):
            raise RuntimeError(f"encode_context: x_c must be (B, T, {self.feature_dim}) or (B, T, "
                               f"{self.motion_feature_dim}), got {x_c.shape}")
        motion_only = x_c.size(2) == self.motion_feature_dim
        if motion_only:
            x_c = torch.cat([x_c, torch.zeros(x_c.size(0), x_c.size(1), self.feature_dim - self.motion_feature_dim,
                                              dtype=x_c.dtype)], 2)
        m = mask.to(torch.bool)
        if y_c.dim() != 3 or y_c.size(2) != 6 or m.shape != x_c.shape[:2] or y_c.shape[:2] != x_c.shape[:2]:
            raise RuntimeError("encode_context: y_c must be (B, T, 6) and mask (B, T), as x_c")
        keys_in, values, z_mu, z_sigma = self.inner.encode_context(x_c[:, :, :self.motion_feature_dim].contiguous(), y_c, m)
        k = int(m.sum())
        cross_validated = not motion_only and self.blend_folds > 0 and x_c.size(0) > 1
        if may_skip and (motion_only or (cross_validated and self.min_fast_turns > 0.0
                                         and float(self.fast_turn_share(x_c, m)) < self.min_fast_turns)):
            return self._cchp_alone_keys(keys_in, k), values, z_mu, z_sigma
        s_all = self.encoder(torch.nan_to_num(x_c[:, :, self.motion_feature_dim:][m], 0.0, 0.0, 0.0)).to(torch.float64)
        mean = s_all.mean(0)
        spread = s_all.std(0, unbiased=False) + 1e-6
        s_all = (s_all - mean) / spread
        # The anchors: every step of a context of at most `kernel_anchors`, else that many spread evenly.
        a = self._anchors(k)
        if a < k:
            anchor = torch.floor(torch.arange(a, dtype=torch.float64) * (float(k) / float(a))).to(torch.int64)
        else:
            anchor = torch.arange(k)
        s = s_all[anchor]
        d = torch.cdist(s, s)
        apart = d[d > 0]
        width = self.kernel_bandwidth * (apart.median() if apart.numel() > 0 else torch.ones((), dtype=torch.float64))
        gram = torch.exp(-d ** 2 / (2.0 * width ** 2))
        m_inv = torch.linalg.inv(gram + self.kernel_lambda * torch.eye(a, dtype=torch.float64))
        # The context's own labels: a CCHP with `label_lead` reads labels that many steps later (its
        # `values`); the kernel read, chosen on recorded people, reads the labels as they are.
        y_all = torch.nan_to_num(y_c[m].to(torch.float64), 0.0, 0.0, 0.0)
        y_anchor = y_all[anchor]
        w = torch.mm(m_inv, y_anchor)
        # Each axis's command size: the largest label on it in the context (0: never commanded).
        sizes = y_all.abs().max(0)[0]
        blend = torch.full((1,), self.kernel_blend, dtype=torch.float64)
        fitted = torch.full((1,), self.kernel_blend, dtype=torch.float64)
        gain = torch.full((1,), -1.0, dtype=torch.float64)  # -1: not cross-validated
        cchp_error = torch.full((1,), -1.0, dtype=torch.float64)
        if motion_only:
            blend = torch.zeros(1, dtype=torch.float64)
        elif cross_validated:
            fitted_a, gain_a, cchp_a = self._cross_validated_blend(x_c, y_c, m, m_inv, y_anchor, anchor, sizes)
            fitted, gain, cchp_error = fitted_a.view(1), gain_a.view(1), cchp_a.view(1)
            used = (float(gain_a) >= self.min_gain and float(cchp_a) >= self.min_cchp_error
                    and float(fitted_a) >= self.min_blend
                    and (self.min_fast_turns <= 0.0 or float(self.fast_turn_share(x_c, m)) >= self.min_fast_turns))
            blend = fitted if used else torch.zeros(1, dtype=torch.float64)
        parts = [mean, spread, width.view(1), blend]
        if self.commit_share > 0:
            parts.append(sizes)
        # The kernel read's part: over the anchors, M, s, W, |s|^2 and each anchor's step in the context,
        # each row-major; then the extras; then the match's block (K rows).
        own = [m_inv.reshape(-1), s.reshape(-1), w.reshape(-1), (s * s).sum(1), anchor.to(torch.float64)]
        if self.match_share > 0:
            f = self._match_frames(torch.nan_to_num(x_c[:, :, self.motion_feature_dim:][m], 0.0, 0.0, 0.0
                                                    ).to(torch.float64))
            f_mean = f.mean(0)
            f_spread = f.std(0, unbiased=False) + 1e-6
            position = (torch.cumsum(m.to(torch.int64), 1) - 1)[m].to(torch.float64)
            clip = torch.arange(m.size(0)).view(-1, 1).expand(m.size(0), m.size(1))[m].to(torch.float64)
            fits = torch.ones(1, dtype=torch.float64) if k <= self.match_max_steps else torch.zeros(1, dtype=torch.float64)
            parts += [f_mean, f_spread, fits]
            frames = (f - f_mean) / f_spread
            weighted_square = (frames * frames * self.match_weight.to(torch.float64)).sum(1, keepdim=True)
            parts += [fitted, gain]
            own += [torch.cat(parts),
                    torch.cat([frames, weighted_square, y_all, position.view(-1, 1), clip.view(-1, 1)], 1).reshape(-1)]
        else:
            own.append(torch.cat(parts + [fitted, gain]))
        own.append(cchp_error)  # last, so that every part before it keeps its place in memory
        return self._keys_block(keys_in, k, torch.cat(own).to(torch.float32)), values, z_mu, z_sigma

    def _keys_block(self, keys_in: torch.Tensor, k: int, own_flat: torch.Tensor) -> torch.Tensor:
        """One (K, D_in + ceil(own / K)) block whose memory is the CCHP's keys, then the kernel read's part
        (`own_flat`, at most `_own_size(K)` floats): each part is read as a view of it, without a copy."""
        d_in = keys_in.size(1)
        cols = d_in + (self._own_size(k) + k - 1) // k
        flat = torch.zeros(k * cols, dtype=torch.float32)
        flat[:k * d_in] = keys_in.reshape(-1)
        flat[k * d_in:k * d_in + own_flat.numel()] = own_flat
        return flat.view(k, cols)

    def _cchp_alone_keys(self, keys_in: torch.Tensor, k: int) -> torch.Tensor:
        """The keys of a context read by the CCHP alone: the kernel read's part zeros but for A (0), A as
        fitted (the fixed blend: not cross-validated), the gain and the CCHP's own error (-1: not measured)."""
        own = torch.zeros(self._own_size(k), dtype=torch.float32)
        a = self._anchors(k)
        at = a * (a + self.shape_dim + 8)
        own[at + self.extra_size - 2] = self.kernel_blend
        own[at + self.extra_size - 1] = -1.0
        own[self._own_size(k) - 1] = -1.0
        return self._keys_block(keys_in, k, own)

    def _committed(self, r: torch.Tensor, sizes: torch.Tensor) -> torch.Tensor:
        """Rows of kernel reads (N, 6), each (1 - share) as it is + share x its dominant command (the axis
        largest as a share of its size in the context), at full size from commit_high of it, scaled
        down linearly to none at commit_low."""
        if self.commit_share <= 0:
            return r
        known = sizes > 0
        s = torch.where(known, r / torch.where(known, sizes, torch.ones_like(sizes)), torch.zeros_like(r))
        axis = s.abs().argmax(1, keepdim=True)
        size = s.gather(1, axis)
        sure = torch.clamp((size.abs() - self.commit_low) / (self.commit_high - self.commit_low), 0.0, 1.0)
        command = torch.zeros_like(r).scatter(1, axis, sure * torch.sign(size) * sizes[axis.view(-1)].view(-1, 1))
        return self.commit_share * command + (1.0 - self.commit_share) * r

    def _cross_validated_blend(self, x_c: torch.Tensor, y_c: torch.Tensor, m: torch.Tensor, m_inv: torch.Tensor,
                               y_anchor: torch.Tensor, anchor: torch.Tensor, sizes: torch.Tensor
                               ) -> Tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
        """A in [0, 1] that best blends the two reads on the person's own clips, each clip read with
        the clips of the other folds as context (clip b is in fold b mod F): the CCHP stepped over
        the clip (its own mean fed back, z the prior mean), the kernel read from the exact
        leave-fold-out solution of the whole solve over the anchors (Y_S - (M_SS)^-1 (M Y)_S for the
        fold's anchors S). Least squares over every anchor step of `blend_rows` clips spread over the
        context (every step, when each is an anchor). Returns (A, the gain): the gain is the share of
        the CCHP's squared error over those steps that the blend removes, cross-fitted so that it is not
        flattered by A's own fit: the clips stepped through are taken alternately into two halves, and
        each half is read with the A fitted on the other. Last, the CCHP's own squared error over those
        steps as a share of the labels' (of commanding zero twist's; -1 where there were none)."""
        n_rows = x_c.size(0)
        folds = min(self.blend_folds, n_rows)
        counts = m.sum(1)
        starts = torch.cumsum(counts, 0) - counts
        n_steps = int(counts.sum())
        a = anchor.size(0)
        anchor_of = torch.full((n_steps,), -1, dtype=torch.int64)
        anchor_of[anchor] = torch.arange(a)
        fitted_residual = torch.mm(m_inv, y_anchor)  # (M Y): the full solve's residuals, scaled
        stride = max(1, n_rows // self.blend_rows)
        sums = torch.zeros(n_rows, 3, dtype=torch.float64)  # per clip: (k - c).(y - c), |k - c|^2, |y - c|^2
        label_square = torch.zeros((), dtype=torch.float64)  # |y|^2 over the same steps
        hi = self.inner_hidden
        for f in range(folds):
            out_rows: List[int] = []
            in_rows: List[int] = []
            spans: List[torch.Tensor] = []
            for b in range(n_rows):
                if b % folds == f:
                    out_rows.append(b)
                    spans.append(torch.arange(int(starts[b]), int(starts[b] + counts[b])))
                else:
                    in_rows.append(b)
            in_fold = anchor_of[torch.cat(spans)]
            in_fold = in_fold[in_fold >= 0]  # the fold's anchors, S
            if in_fold.numel() == 0:
                continue
            row_of = torch.full((a,), -1, dtype=torch.int64)
            row_of[in_fold] = torch.arange(in_fold.size(0))
            loo = self._committed(y_anchor[in_fold] - torch.linalg.solve(m_inv[in_fold][:, in_fold],
                                                                          fitted_residual[in_fold]), sizes)
            keep = torch.tensor(in_rows)
            keys, values, z, _ = self.inner.encode_context(
                x_c[keep][:, :, :self.motion_feature_dim].contiguous(), y_c[keep], m[keep])
            for b in out_rows:
                n = int(counts[b])
                if b % stride == 0:
                    h = torch.zeros(hi)
                    c = torch.zeros(hi)
                    y_prev = torch.zeros(6)
                    for t in range(n):
                        y_prev, _, h, c, _, _, _ = self.inner.step_read(
                            torch.nan_to_num(x_c[b, t, :self.motion_feature_dim], 0.0, 0.0, 0.0), y_prev, h, c,
                            keys, values, z)
                        j = int(anchor_of[int(starts[b]) + t])
                        if j >= 0:
                            gap = loo[int(row_of[j])] - y_prev.to(torch.float64)
                            miss = y_anchor[j] - y_prev.to(torch.float64)
                            sums[b, 0] += (gap * miss).sum()
                            sums[b, 1] += (gap * gap).sum()
                            sums[b, 2] += (miss * miss).sum()
                            label_square += (y_anchor[j] * y_anchor[j]).sum()
        cchp_error = sums[:, 2].sum() / label_square if float(label_square) > 0 else torch.full((), -1.0, dtype=torch.float64)
        if sums[:, 1].sum() <= 0:
            return (torch.full((), self.kernel_blend, dtype=torch.float64), torch.full((), -1.0, dtype=torch.float64),
                    cchp_error)
        fitted, gain = blend_and_gain(sums, stride)
        return fitted, gain, cchp_error

    def _blend(self, keys: torch.Tensor) -> torch.Tensor:
        return self._blend_of(self._extras(keys))

    def _blend_of(self, extras: torch.Tensor) -> torch.Tensor:
        """A, from `_extras(keys)`."""
        return extras[2 * self.shape_dim + 1]

    @torch.jit.export
    def blend_choice(self, keys: torch.Tensor) -> torch.Tensor:
        """[A used, A as fitted, the share of the CCHP's squared error over the person's own clips that the
        blend removes, cross-fitted, the CCHP's own squared error there as a share of zero twist's (-1: not
        cross-validated)] for encoded keys."""
        extras = self._extras(keys)
        return torch.stack([extras[2 * self.shape_dim + 1], extras[self.extra_size - 2], extras[self.extra_size - 1],
                            self._own(keys)[self._own_size(keys.size(0)) - 1]])

    def _kernel(self, q: torch.Tensor, keys: torch.Tensor, extras: torch.Tensor) -> torch.Tensor:
        """k (1, a) of a standardised query (1, shape_dim) against the anchors; `extras` is `_extras(keys)`.
        |q - s_i|^2 = |s_i|^2 - 2 s_i . q + |q|^2, read from the keys in place."""
        a = self._anchors(keys.size(0))
        s = self._anchor_part(keys, a, self.shape_dim)
        square = self._anchor_part(keys, a + self.shape_dim + 6, 1).view(-1)
        q = q.view(-1)
        d2 = torch.clamp(square - 2.0 * torch.mv(s, q) + (q * q).sum(), min=0.0)
        width = extras[2 * self.shape_dim]
        return torch.exp(-d2 / (2.0 * width ** 2)).view(1, -1)

    def _standardise(self, x: torch.Tensor, extras: torch.Tensor) -> torch.Tensor:
        x = self.encoder(torch.nan_to_num(x, 0.0, 0.0, 0.0).view(1, -1))
        return ((x - extras[:self.shape_dim]) / extras[self.shape_dim:2 * self.shape_dim]).view(1, -1)

    @torch.jit.export
    def attention_of(self, query: torch.Tensor, keys: torch.Tensor) -> torch.Tensor:
        """[K]: A k M + (1 - A) the CCHP's attention (mean over its heads); k M over the anchors, 0 on the
        steps that are not anchors."""
        k = keys.size(0)
        a = self._anchors(k)
        inner = self.inner.attention_of(query[:self.inner_query_size], self._inner_keys(keys))
        if inner.dim() == 2:
            inner = inner.mean(0)
        a_blend = self._blend(keys)
        if float(a_blend) == 0.0:  # the CCHP alone for this person
            return inner
        kernel = torch.mm(self._kernel(query[self.inner_query_size:].view(1, -1), keys, self._extras(keys)),
                          self._anchor_part(keys, 0, a)).view(-1)
        if a < k:
            step_of = self._anchor_part(keys, a + self.shape_dim + 7, 1).view(-1).to(torch.int64)
            kernel = torch.zeros(k).index_add_(0, step_of, kernel)
        return a_blend * kernel + (1.0 - a_blend) * inner

    def _step(self, x_t: torch.Tensor, h: torch.Tensor, c: torch.Tensor, keys: torch.Tensor,
              values: torch.Tensor, z: torch.Tensor
              ) -> Tuple[torch.Tensor, torch.Tensor, torch.Tensor, torch.Tensor, torch.Tensor, torch.Tensor,
                         torch.Tensor]:
        if x_t.numel() == self.motion_feature_dim:  # the paper's 36 alone: no path and shape
            x_t = torch.cat([x_t.view(-1), torch.zeros(self.feature_dim - self.motion_feature_dim, dtype=x_t.dtype)])
        if x_t.numel() != self.feature_dim:
            raise RuntimeError(f"step: x_t must have {self.feature_dim} (or {self.motion_feature_dim}) features, "
                               f"got {x_t.numel()}")
        k = keys.size(0)
        a = self._anchors(k)
        x_t = x_t.view(-1)
        hi = self.inner_hidden
        mean_i, std, h2, c2, read_i, v, query_i = self.inner.step_read(
            x_t[:self.motion_feature_dim], h[hi:hi + 6], h[:hi], c[:hi], self._inner_keys(keys), values, z)
        extras = self._extras(keys)
        a_blend = self._blend_of(extras)
        if float(a_blend) == 0.0:
            # The CCHP alone for this person (A = 0): its own step, exactly, without the kernel read's cost
            # (the query's path-and-shape part, which only the kernel read's attention reads, is zeros).
            h_next = torch.cat([h2, mean_i, torch.zeros(self.match_max_steps)])
            c_next = torch.cat([c2, torch.zeros(6 + self.match_max_steps)])
            return (mean_i, std, h_next, c_next, read_i.mean(0).view(1, 6), v,
                    torch.cat([query_i, torch.zeros(self.shape_dim, dtype=query_i.dtype)]))
        q = self._standardise(x_t[self.motion_feature_dim:], extras)
        read_k = torch.mm(self._kernel(q, keys, extras), self._anchor_part(keys, a + self.shape_dim, 6))
        if self.commit_share > 0:
            read_k = self._committed(read_k.to(torch.float64), extras[2 * self.shape_dim + 2:2 * self.shape_dim + 8]
                                     ).to(read_k.dtype)
        read_k = read_k.view(6)
        h_next = torch.cat([h2, mean_i])
        c_next = torch.cat([c2, torch.zeros(6)])
        if self.match_share > 0:
            if float(extras[self.match_extras_at + 2 * self.match_frame_dim]) > 0.0:
                read_m, cost, length = self._match(x_t[self.motion_feature_dim:], h[hi + 6:], c[hi + 6:], keys, extras)
                read_k = (1.0 - self.match_share) * read_k + self.match_share * read_m
            else:  # a context longer than the match's state holds: the kernel read alone
                cost = torch.zeros(self.match_max_steps)
                length = torch.zeros(self.match_max_steps)
            h_next = torch.cat([h_next, cost])
            c_next = torch.cat([c_next, length])
        mean = a_blend * read_k + (1.0 - a_blend) * mean_i
        read = (a_blend * read_k + (1.0 - a_blend) * read_i.mean(0)).view(1, 6)
        return (mean, std, h_next, c_next, read, v, torch.cat([query_i, q.view(-1)]))

    def _match(self, p: torch.Tensor, cost: torch.Tensor, length: torch.Tensor, keys: torch.Tensor,
               extras: torch.Tensor) -> Tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
        """One step of the time warp: (read (6), cost, length), cost and length padded to
        match_max_steps. Each context step i keeps the least mean cost of matching the stream's recent
        steps to its clip from the clip's first step up to i (length 0: no match yet), by steps of
        (1, 1) (or a fresh start at a clip's first step), (1, 0) and (1, 2); each clip's best step gives
        its labels there, weighted by exp(-(its mean cost - the best clip's) / tau). `extras` is
        `_extras(keys)`."""
        k = keys.size(0)
        at = self.match_extras_at
        block = self._match_block(keys)
        fd = self.match_frame_dim
        frames, weighted_square = block[:, :fd], block[:, fd]
        labels = block[:, fd + 1:fd + 7]
        position, clip = block[:, fd + 7], block[:, fd + 8].to(torch.int64)
        f = self._match_frames(torch.nan_to_num(p, 0.0, 0.0, 0.0).view(1, -1))
        f = ((f - extras[at:at + fd]) / extras[at + fd:at + 2 * fd]).view(-1)
        # d_i = sum_j w_j (frame_ij - f_j)^2, from the keys in place.
        wf = self.match_weight * f
        d = torch.clamp(weighted_square - 2.0 * torch.mv(frames, wf) + (wf * f).sum(), min=0.0)
        length = length[:k]
        cost = torch.where(length > 0, cost[:k], torch.full_like(d, self.match_none))
        none1 = torch.full((1,), self.match_none)
        zero1 = torch.zeros(1)
        diag = torch.where(position > 0, torch.cat([none1, cost[:-1]]), torch.zeros_like(d))
        diag_length = torch.where(position > 0, torch.cat([zero1, length[:-1]]), torch.zeros_like(d))
        skip = torch.where(position > 1, torch.cat([none1, none1, cost[:-2]])[:k], torch.full_like(d, self.match_none))
        skip_length = torch.cat([zero1, zero1, length[:-2]])[:k]
        # The least of the three mean costs, the first on a tie.
        v_diag = (diag + d) / (diag_length + 1.0)
        v_stay = (cost + d) / (length + 1.0)
        v_skip = (skip + d) / (skip_length + 1.0)
        pick_diag = (v_diag <= v_stay) & (v_diag <= v_skip)
        pick_stay = (v_stay <= v_skip) & ~pick_diag
        cost = torch.where(pick_diag, diag, torch.where(pick_stay, cost, skip)) + d
        length = torch.where(pick_diag, diag_length, torch.where(pick_stay, length, skip_length)) + 1.0
        mean_cost = cost / length
        clips = int(clip[-1]) + 1  # the clips are numbered in order
        best = torch.full((clips,), self.match_none).scatter_reduce(0, clip, mean_cost, reduce="amin", include_self=True)
        winner = (mean_cost <= best[clip]).to(d.dtype)
        ties = torch.zeros(clips).scatter_add(0, clip, winner)
        w = winner * torch.exp(-(mean_cost - mean_cost.min()) / self.match_tau) / ties[clip]
        read = (w.view(-1, 1) * labels).sum(0) / w.sum()
        pad = torch.zeros(self.match_max_steps - k)
        return read, torch.cat([cost, pad]), torch.cat([length, pad])


def encode_fitted(module, x_c: torch.Tensor, y_c: torch.Tensor, mask: torch.Tensor):
    """`module.encode_context`, with a path-and-shape file's kernel read fitted and cross-validated whatever
    its fast-turn gate says (`encode_context_fitted`, where the file has it): for reports and measurements
    of that read."""
    return getattr(module, "encode_context_fitted", module.encode_context)(x_c, y_c, mask)


def turned_away_by_fast_turns(module, x_c, mask) -> bool:
    """True when a path-and-shape file's fast-turn gate reads this context with the CCHP alone.

    `x_c` (B, T, >= 36) and `mask` (B, T), numpy or torch, as `pack_context` gives them; only the 36
    hand-part velocities are looked at, so the caller need not build the hand's path and shape to ask.
    The test is the file's own (`_encode`): the gate is on, the context has more than one clip (else the
    blend is not cross-validated), and the palm turns fast in too few of its moving steps. A file
    without the gate, or any other file, gives False. For such a context the file's encoding of the 36
    features alone equals that of the full features (the keys, values and latent), and so does every
    step: a caller may then give it the 36 features and skip the path and shape."""
    if not all(hasattr(module, a) for a in ("fast_turn_share", "min_fast_turns", "blend_folds")):
        return False
    if float(module.min_fast_turns) <= 0.0 or int(module.blend_folds) <= 0 or int(x_c.shape[0]) <= 1:
        return False
    x = torch.as_tensor(x_c)[:, :, :FEATURE_DIM]
    m = torch.as_tensor(mask).to(torch.bool)
    return float(module.fast_turn_share(x, m)) < float(module.min_fast_turns)


def _min_gain(text: str) -> float:
    """`--min-gain`: a share in [0, 1), or 'off' (GAIN_CONDITION_OFF)."""
    if text.strip().lower() == "off":
        return GAIN_CONDITION_OFF
    try:
        value = float(text)
    except ValueError:
        value = -1.0
    if not 0.0 <= value < 1.0:
        raise argparse.ArgumentTypeError(f"expected a share in [0, 1) or 'off', got {text!r}")
    return value


def build_path_shape_policy(policy: os.PathLike, out: os.PathLike, blend: float = DEFAULT_BLEND,
                            bandwidth: float = DEFAULT_BANDWIDTH, lam: float = DEFAULT_LAMBDA,
                            folds: int = DEFAULT_CV_FOLDS, rows: int = DEFAULT_CV_ROWS,
                            encoder: Optional[os.PathLike] = None,
                            commit: Tuple[float, float, float] = (DEFAULT_COMMIT_SHARE, COMMIT_LOW, COMMIT_HIGH),
                            match: Tuple[float, float, float] = (DEFAULT_MATCH_SHARE, MATCH_VELOCITY_WEIGHT, MATCH_TAU),
                            anchors: int = DEFAULT_ANCHORS, min_gain: float = DEFAULT_MIN_GAIN,
                            hold: Tuple[float, float, float, float, float] = DEFAULT_HOLD,
                            min_cchp_error: float = DEFAULT_MIN_CCHP_ERROR,
                            min_blend: float = DEFAULT_MIN_BLEND,
                            min_fast_turns: float = DEFAULT_MIN_FAST_TURNS) -> pathlib.Path:
    """Writes the extended policy file, its model card extended with the read's settings (and, with
    `encoder`, the kernel reading the embedding of that `learning.hand_encoder` file)."""
    from rtcohand_drake.learning.export import policy_and_card, save_scripted
    from rtcohand_drake.learning.hand_encoder import load_encoder

    inner, card = policy_and_card(policy)  # checked as load_policy checks a policy file
    if int(inner.feature_dim) != FEATURE_DIM:
        raise InputError(f"{policy}: already reads {int(inner.feature_dim)} features; give a 36-feature CCHP policy")
    encoder_module, encoder_card = load_encoder(encoder) if encoder is not None else (None, None)
    with warnings.catch_warnings():
        warnings.filterwarnings("ignore", category=DeprecationWarning, module=r"torch\.jit")
        scripted = torch.jit.script(PathShapeKernelPolicy(inner, blend, bandwidth, lam, folds, rows,
                                                          encoder_module, tuple(commit), tuple(match),
                                                          anchors, min_gain, tuple(hold), min_cchp_error,
                                                          min_blend, min_fast_turns).eval())
    card = dict(card, path_shape_read={
        "inner_policy": pathlib.Path(policy).name, "blend": blend, "bandwidth": bandwidth, "lambda": lam,
        "blend_folds": folds, "blend_rows": rows, "anchors": anchors,
        "min_gain": None if min_gain == GAIN_CONDITION_OFF else min_gain,
        "min_cchp_error": min_cchp_error,
        **({"min_blend": min_blend} if min_blend > 0 else {}),
        **({"min_fast_turns": min_fast_turns, "fast_turn_rad_s": FAST_TURN_RAD_S} if min_fast_turns > 0 else {}),
        "feature_dim": FEATURE_DIM + PATH_SHAPE_DIM,
        **({"commit": list(commit)} if commit[0] > 0 else {}),
        **({"match": list(match), "match_max_steps": MATCH_MAX_STEPS} if match[0] > 0 else {}),
        **({"command_hold": list(hold)} if hold[4] > 0 else {}),
        "features": "36 hand-part velocities, then the hand's path and shape (hand_features.PathShapeStream)"})
    if encoder_card is not None:
        card["path_shape_read"]["encoder"] = dict(encoder_card, file=pathlib.Path(encoder).name)
    return save_scripted(scripted, out, card)


def make_parser() -> argparse.ArgumentParser:
    from rtcohand_drake.errors import ArgumentParser

    p = ArgumentParser(prog="python -m rtcohand_drake.learning.path_shape_policy",
                       description=__doc__.splitlines()[0])
    p.add_argument("--policy", required=True, help="an exported 36-feature CCHP policy file")
    p.add_argument("--out", required=True)
    p.add_argument("--blend", type=float, default=DEFAULT_BLEND, help="A: the kernel read's share of the mean")
    p.add_argument("--bandwidth", type=float, default=DEFAULT_BANDWIDTH, help="b / the median distance")
    p.add_argument("--lambda", dest="lam", type=float, default=DEFAULT_LAMBDA)
    p.add_argument("--folds", type=int, default=DEFAULT_CV_FOLDS,
                   help="choose A per context by this many folds of its clips (0: A fixed at --blend)")
    p.add_argument("--rows", type=int, default=DEFAULT_CV_ROWS, help="clips the choice of A steps through, at most")
    p.add_argument("--commit", type=float, nargs=3, metavar=("SHARE", "LOW", "HIGH"),
                   default=[DEFAULT_COMMIT_SHARE, COMMIT_LOW, COMMIT_HIGH],
                   help="commit SHARE of the kernel read to its dominant command, full from HIGH of its size, "
                        "none below LOW (SHARE 0: off)")
    p.add_argument("--match", type=float, nargs=3, metavar=("SHARE", "VELOCITY_WEIGHT", "TAU"),
                   default=[DEFAULT_MATCH_SHARE, MATCH_VELOCITY_WEIGHT, MATCH_TAU],
                   help="SHARE of the kernel read replaced by the stroke matched against each context clip with a "
                        "time warp (SHARE 0: off)")
    p.add_argument("--anchors", type=int, default=DEFAULT_ANCHORS,
                   help="the context steps the kernel read is fitted on, at most (a longer context: that many, "
                        "spread evenly over it)")
    p.add_argument("--min-gain", type=_min_gain, default=DEFAULT_MIN_GAIN,
                   help="use a person's kernel read only if the fitted blend removes at least this share of the "
                        "CCHP's squared error over their own clips ('off': no such condition)")
    p.add_argument("--min-cchp-error", type=float, default=DEFAULT_MIN_CCHP_ERROR,
                   help="use a person's kernel read only if the CCHP alone, cross-validated over their own clips, "
                        "reads them with at least this share of zero twist's squared error (0: for anyone)")
    p.add_argument("--min-blend", type=float, default=DEFAULT_MIN_BLEND,
                   help="use a person's kernel read only if the blend fitted on their own clips gives it at least "
                        "this share A (0: any A; above 1: the CCHP alone for everyone)")
    p.add_argument("--min-fast-turns", type=float, default=DEFAULT_MIN_FAST_TURNS,
                   help=f"use a person's kernel read only if their palm turns faster than {FAST_TURN_RAD_S:g} rad/s in "
                        "at least this share of their clips' moving steps (0: any context)")
    p.add_argument("--hold", type=float, nargs=5, metavar=("HIGH", "STEPS_ON", "LOW", "STEPS_OFF", "SHARE"),
                   default=list(DEFAULT_HOLD),
                   help="ask the policy box to hold SHARE of a command at its full size once the output has pointed "
                        "along it at HIGH of its size for STEPS_ON steps, until it falls under LOW for STEPS_OFF "
                        "steps (learning.command_hold; SHARE 0: no hold)")
    p.add_argument("--encoder", default=None,
                   help="a learning.hand_encoder file: the kernel reads the path and shape through it")
    return p


def main(argv: Optional[Sequence[str]] = None) -> int:
    args = make_parser().parse_args(argv)
    out = build_path_shape_policy(args.policy, args.out, args.blend, args.bandwidth, args.lam, args.folds, args.rows,
                                  args.encoder, tuple(args.commit), tuple(args.match), args.anchors,
                                  args.min_gain, tuple(args.hold), args.min_cchp_error, args.min_blend,
                                  args.min_fast_turns)
    print(f"wrote {out}")
    return 0


def entry_point() -> None:
    sys.exit(run_cli(main, prog="rtcohand_drake.learning.path_shape_policy"))


if __name__ == "__main__":
    entry_point()
