"""CCHP: the conditional collaborative handling process (paper, "Neural Network
Architecture of CCHP"), one small module per block of the paper's diagram, with
the ELBO written next to it.

Shapes: B batch items, T target steps, P context pieces per item, Tc steps per
piece, H hidden size, Dz latent size. Features x are (.., 36) hand-part
velocities, labels y are (.., 6) workpiece twists (Tx Ty Tz Rx Ry Rz).
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass, field
from typing import Dict, List, Optional, Tuple

import torch
from torch import nn

from rtcohand_drake.learning.batching import Batch
from rtcohand_drake.learning.nets.blocks import (
    FEATURE_DIM,
    MOTION_DIM,
    NUM_PARTS,
    PART_DIM,
    Normalizer,
    PerDimensionMLP,
    bounded_std,
    gaussian_kl,
    gaussian_log_prob,
    mlp,
)


@dataclass
class CchpConfig:
    """Network sizes. Defaults: paper appendix, table "MLP configurations"."""

    hidden_size: int = 128  # H, LSTM cell state
    finger_sizes: List[int] = field(default_factory=lambda: [PART_DIM, 32, 32])  # f_finger
    hand_hidden: List[int] = field(default_factory=lambda: [128, 64])  # f_hand hidden layers
    hand_feature_size: int = 32  # f_hand output
    aggregate_sizes: List[int] = field(default_factory=lambda: [128, 128, 128, 128])  # f_a after its input
    latent_trunk_sizes: List[int] = field(default_factory=lambda: [128, 128, 128, 128, 128])  # f_phi
    latent_dim: int = 32  # D_z
    key_size: int = 32  # f_kq output
    attention_heads: int = 1  # 1, or 6 (one head per motion dimension)
    # What the attention's keys and query are computed from: "state", the
    # encoder cell's hidden state h (paper), or "gesture", the state of a
    # second LSTM cell that sees the hand features only. The cell's state h
    # is fed the labels (true ones in the context, the model's own in the
    # target), so "state" keys can match on the previous label rather than
    # on the gesture; "gesture" keys compare the two hand motions alone.
    key_source: str = "state"
    gesture_hidden_size: int = 64  # G, the gesture cell's state ("gesture" keys only)
    # Attention scores: "dot", q.k / sqrt(key_size) (paper), or "distance",
    # -|q - k|^2: a Gaussian kernel on the projected states, which learns to
    # pick out the context steps nearest to the query much sooner.
    attention_kernel: str = "dot"
    # True: the mean is the context read plus f_y's output (f_y learns a
    # correction to the read); False: f_y's output alone (paper).
    read_skip: bool = False
    # How the context is read: "attention", a softmax over the context steps (paper), or
    # "bayes_linear", a closed-form Bayesian linear regression of the context's labels on
    # gesture features phi(t) (`BayesLinearRead`; needs key_source "gesture"). phi is a learned
    # projection (phi_size) of the gesture cell's state, plus the normalised features x(t)
    # themselves when phi_raw, plus a constant; blr_lambda is the initial prior precision.
    read: str = "attention"
    phi_size: int = 64
    phi_raw: bool = True
    blr_lambda: float = 30.0
    # phi also holds a learned projection (phi_window_size) of the last phi_window frames of
    # the normalised features (0: none); the exported step carries those frames in its state.
    phi_window: int = 0
    phi_window_size: int = 64
    # phi also holds the sum over those phi_window frames of x |x| (36, elementwise; no parameters):
    # the direction of an asymmetric stroke, such as a finger sweep whose fast stroke carries the
    # sign, which no linear function of the frames shows (their sum over a back-and-forth is ~0).
    phi_signed_square: bool = False
    # The prior precision on those 36 signed-square features: "fixed", blr_lambda as for the rest
    # of phi; "context", blr_lambda * phi_signed_square_prior_weight * the feature's mean square over
    # the context, the same as a ridge on that block standardised by the person's own clips (its
    # scale varies a hundredfold between people; the learned part of phi has a trained scale).
    phi_signed_square_prior: str = "fixed"
    phi_signed_square_prior_weight: float = 1.0
    # Clamp each signed-square feature of a live step to the range the context's steps show (no
    # parameters; `BayesLinearRead.clamp_block`). The block's weights for a motion the context lacks
    # rest on almost no data, so a live gesture that excites those features beyond anything in the
    # context reads wild; clamped, it reads no more than the context's own largest stroke.
    phi_signed_square_clamp: bool = False
    # The read leads the labels by this many steps (0: it reads the label of the same step): the
    # Bayesian linear read is solved for the label label_lead steps after each context step, and the
    # decoder is trained on the target's labels shifted alike, so the command comes before the
    # handler's reaction delay that the labels carry (`lead_labels`; bayes_linear only).
    label_lead: int = 0
    output_hidden: List[int] = field(default_factory=lambda: [128, 64])  # f_y hidden layers
    std_min: float = 0.1  # lower bound of the predicted std, in label-scale units
    latent_std_min: float = 0.1  # lower bound of sigma_z

    def to_dict(self) -> Dict:
        return asdict(self)

    @property
    def gesture_size(self) -> int:
        """Size of the gesture cell's state (0 without one)."""
        return self.gesture_hidden_size if self.key_source == "gesture" else 0

    @property
    def state_size(self) -> int:
        """Size of the recurrent state the decoder carries: h, then the gesture cell's state."""
        return self.hidden_size + self.gesture_size


class FingerFeatures(nn.Module):
    """f_finger applied to each of the 6 hand parts: (.., 36) -> (.., 6 * H')."""

    def __init__(self, cfg: CchpConfig):
        super().__init__()
        self.net = mlp(cfg.finger_sizes)
        self.out_size = NUM_PARTS * cfg.finger_sizes[-1]

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        parts = x.reshape(x.shape[:-1] + (NUM_PARTS, PART_DIM))
        return self.net(parts).flatten(-2)


class EncoderCell(nn.Module):
    """f_enc: (finger features of x(t), y(t-1), h(t-1), c(t-1)) -> (h(t), c(t)).

    f_hand sees the part features and h(t-1); the LSTM cell sees the hand
    feature and y(t-1). The finger features do not depend on the recurrence,
    so callers compute them for all steps at once with `fingers`.

    With "gesture" keys a second LSTM cell runs on the finger features alone;
    its state is appended to h and c, so the state is (.., H + G).
    """

    def __init__(self, cfg: CchpConfig):
        super().__init__()
        self.hidden_size = cfg.hidden_size
        self.fingers = FingerFeatures(cfg)
        self.hand = mlp([self.fingers.out_size + cfg.hidden_size] + list(cfg.hand_hidden) + [cfg.hand_feature_size])
        self.lstm = nn.LSTMCell(cfg.hand_feature_size + MOTION_DIM, cfg.hidden_size)
        self.gesture = nn.LSTMCell(self.fingers.out_size, cfg.gesture_size) if cfg.gesture_size else None

    def forward(
        self, finger_feat: torch.Tensor, y_prev: torch.Tensor, h: torch.Tensor, c: torch.Tensor
    ) -> Tuple[torch.Tensor, torch.Tensor]:
        n = self.hidden_size
        h_main = h[..., :n]
        hand_feat = torch.relu(self.hand(torch.cat([finger_feat, h_main], -1)))
        h_new, c_new = self.lstm(torch.cat([hand_feat, y_prev], -1), (h_main, c[..., :n]))
        if self.gesture is None:
            return h_new, c_new
        g, cg = self.gesture(finger_feat, (h[..., n:], c[..., n:]))
        return torch.cat([h_new, g], -1), torch.cat([c_new, cg], -1)


class LatentEncoder(nn.Module):
    """f_a, mean over time, f_phi and two Gaussian heads: q(z | x, y).

    The same network gives q(z|C) (context steps only) and q(z|C,T)
    (context and target steps).
    """

    def __init__(self, cfg: CchpConfig):
        super().__init__()
        self.aggregate = mlp([cfg.state_size + MOTION_DIM] + list(cfg.aggregate_sizes))
        self.trunk = nn.Sequential(mlp([cfg.aggregate_sizes[-1]] + list(cfg.latent_trunk_sizes)), nn.ReLU())
        self.mu_head = nn.Linear(cfg.latent_trunk_sizes[-1], cfg.latent_dim)
        self.sigma_head = nn.Linear(cfg.latent_trunk_sizes[-1], cfg.latent_dim)
        self.latent_std_min = cfg.latent_std_min

    def step_features(self, h: torch.Tensor, y: torch.Tensor) -> torch.Tensor:
        return self.aggregate(torch.cat([h, y], -1))

    def from_summary(self, s: torch.Tensor) -> Tuple[torch.Tensor, torch.Tensor]:
        g = self.trunk(s)
        sigma = self.latent_std_min + (1.0 - self.latent_std_min) * torch.sigmoid(self.sigma_head(g))
        return self.mu_head(g), sigma


class ContextAttention(nn.Module):
    """Dot-product attention of a target hidden state over context hidden states.

    f_kq maps keys (context states) and the query (target state) to the same
    space; the values are the context velocities. Keys are projected once per
    context (`project_keys`), for "dot" scores scaled by 1/sqrt(key_size). f_kq reads the
    state from `key_offset` on: all of h ("state" keys) or the gesture cell's
    part ("gesture" keys).
    """

    def __init__(self, cfg: CchpConfig):
        super().__init__()
        self.heads = cfg.attention_heads
        self.key_size = cfg.key_size
        self.key_offset = cfg.hidden_size if cfg.gesture_size else 0
        self.distance = cfg.attention_kernel == "distance"
        self.kq = nn.Linear(cfg.state_size - self.key_offset, cfg.attention_heads * cfg.key_size)

    def project_keys(self, h_c: torch.Tensor) -> torch.Tensor:
        """(..., K, state) -> (..., heads, K, key_size)."""
        k = self.kq(h_c[..., self.key_offset:])
        if not self.distance:
            k = k / math.sqrt(self.key_size)
        k = k.reshape(h_c.shape[:-1] + (self.heads, self.key_size))
        return k.movedim(-2, -3)

    def forward(
        self, h_t: torch.Tensor, keys: torch.Tensor, values: torch.Tensor, key_mask: torch.Tensor
    ) -> Tuple[torch.Tensor, torch.Tensor]:
        """h_t (B, H), keys (B, heads, K, dk), values (B, K, 6), key_mask (B, K).

        Returns r (B, heads, 6) and the weights (B, heads, K).
        """
        q = self.kq(h_t[..., self.key_offset:]).reshape(h_t.shape[0], self.heads, self.key_size, 1)
        if self.distance:
            scores = -((keys - q.transpose(-1, -2)) ** 2).sum(-1)  # (B, heads, K)
        else:
            scores = torch.matmul(keys, q).squeeze(-1)  # (B, heads, K)
        scores = scores.masked_fill(~key_mask.unsqueeze(1), float("-inf"))
        weights = torch.softmax(scores, -1)
        return torch.matmul(weights, values), weights


def blr_prior_precision(phi: torch.Tensor, m: torch.Tensor, lam: torch.Tensor, start: int, stop: int,
                        weight: float) -> torch.Tensor:
    """The Bayesian linear read's prior precision (.., d) for phi (.., K, d) with the step mask
    m (.., K, 1): lam for every feature, and with weight > 0, lam * weight * (mean square over the
    masked steps) for features start:stop (the signed-square block), so that block is read as if
    standardised by the context. Adding diag(prior) to Phi^T Phi equals a ridge on phi / s with
    s^2 = weight * mean square; W and A then stay in phi's own units, so a step is unchanged."""
    prior = lam * torch.ones_like(phi[..., 0, :])
    if weight > 0.0 and stop > start:
        ms = ((phi[..., start:stop] ** 2) * m).sum(-2) / m.sum(-2).clamp_min(1.0)
        scaled = lam * weight * ms.clamp_min(1e-6)
        prior = torch.cat([prior[..., :start], scaled, prior[..., stop:]], -1)
    return prior


def lead_labels(y: torch.Tensor, mask: torch.Tensor, lead: int) -> torch.Tensor:
    """y (N, T, 6) with mask (N, T) True on each sequence's real steps (padded at the end) -> each
    step's label `lead` steps later; a sequence's last real label repeats past its end."""
    if lead <= 0:
        return y
    t_len = y.shape[1]
    last = (mask.to(torch.long).sum(1, keepdim=True) - 1).clamp_min(0)  # (N, 1)
    idx = torch.minimum(torch.arange(t_len, device=y.device).unsqueeze(0) + lead, last)  # (N, T)
    return torch.gather(y, 1, idx.unsqueeze(-1).expand(-1, -1, y.shape[2]))


def clamp_columns(phi: torch.Tensor, lo: torch.Tensor, hi: torch.Tensor, start: int, stop: int) -> torch.Tensor:
    """phi (B, d) with columns start:stop clamped to [lo, hi] (B or 1, stop - start); the Python
    model's and the export's signed-square clamp (`phi_signed_square_clamp`)."""
    block = torch.maximum(torch.minimum(phi[:, start:stop], hi), lo)
    return torch.cat([phi[:, :start], block, phi[:, stop:]], 1)


def signed_square_sum(window: torch.Tensor) -> torch.Tensor:
    """(.., W * 36) frames (oldest first) -> (.., 36): the sum over the W frames of x |x|."""
    frames = window.reshape(window.shape[:-1] + (-1, FEATURE_DIM))
    return (frames * frames.abs()).sum(-2)


class BayesLinearRead(nn.Module):
    """The context read as a Bayesian linear regression over learned gesture features.

    With Phi (K, d) the features of the K context steps and Y (K, 6) their
    labels (label-scale units), the posterior over the map W (d, 6) has
    precision Phi^T Phi + Lambda, so with A = (Phi^T Phi + Lambda)^-1

        r(t) = phi(t)^T A Phi^T Y,     v(t) = 1 + phi(t)^T A phi(t).

    a(t) = phi(t)^T A Phi^T (K) is the equivalent kernel: a signed attention
    over the context steps, r = a . Y. v(t) grows when the live gesture is
    unlike every context gesture; the reported std is scaled by sqrt(v).
    A is computed once per context (a batched Cholesky solve, differentiable,
    so phi is meta-learned through it); a step is then O(d^2). Lambda is
    lambda I, except on the signed-square block with phi_signed_square_prior
    "context" (`blr_prior_precision`).
    """

    def __init__(self, cfg: CchpConfig):
        super().__init__()
        self.proj = nn.Linear(cfg.gesture_size, cfg.phi_size)
        self.raw = cfg.phi_raw
        self.window = cfg.phi_window
        self.window_proj = nn.Linear(cfg.phi_window * FEATURE_DIM, cfg.phi_window_size) if cfg.phi_window else None
        self.signed_square = bool(cfg.phi_signed_square)
        self.dim = (cfg.phi_size + (FEATURE_DIM if cfg.phi_raw else 0) + 1
                    + (cfg.phi_window_size if cfg.phi_window else 0) + (FEATURE_DIM if self.signed_square else 0))
        self.log_lambda = nn.Parameter(torch.tensor(math.log(cfg.blr_lambda)))
        # The signed-square block sits just before the constant; its prior scales with the context
        # when phi_signed_square_prior is "context" (weight 0: the fixed prior).
        if cfg.phi_signed_square_prior not in ("fixed", "context"):
            raise ValueError(f"phi_signed_square_prior must be 'fixed' or 'context', got {cfg.phi_signed_square_prior!r}")
        self.ssq_stop = self.dim - 1
        self.ssq_start = self.ssq_stop - (FEATURE_DIM if self.signed_square else 0)
        self.ssq_prior_weight = (float(cfg.phi_signed_square_prior_weight)
                                 if self.signed_square and cfg.phi_signed_square_prior == "context" else 0.0)
        self.clamp = bool(cfg.phi_signed_square_clamp) and self.signed_square

    @property
    def lam(self) -> torch.Tensor:
        return self.log_lambda.exp()

    def features(self, g: torch.Tensor, x_n: torch.Tensor, window: Optional[torch.Tensor] = None) -> torch.Tensor:
        """phi from the gesture cell's state g (.., G), the normalised features x_n (.., 36) and,
        with phi_window, their last frames `window` (.., phi_window * 36, oldest first)."""
        parts = [self.proj(g)] + ([x_n] if self.raw else [])
        if self.window_proj is not None:
            parts.append(self.window_proj(window))
        if self.signed_square:
            parts.append(signed_square_sum(window))
        return torch.cat(parts + [torch.ones_like(g[..., :1])], -1)

    def windows(self, x_n: torch.Tensor) -> Optional[torch.Tensor]:
        """(N, T, 36) -> (N, T, phi_window * 36): each step's last frames, zeros before the sequence starts."""
        if self.window_proj is None:
            return None
        padded = nn.functional.pad(x_n, (0, 0, self.window - 1, 0))
        return torch.cat([padded[:, k : k + x_n.shape[1]] for k in range(self.window)], -1)

    def fit(self, phi: torch.Tensor, y: torch.Tensor, mask: torch.Tensor) -> Tuple[torch.Tensor, torch.Tensor]:
        """phi (B, K, d), y (B, K, 6), mask (B, K) -> W (B, d, 6), A (B, d, d)."""
        m = mask.unsqueeze(-1).to(phi.dtype)
        phi = phi * m
        prior = blr_prior_precision(phi, m, self.lam, self.ssq_start, self.ssq_stop, self.ssq_prior_weight)
        gram = phi.transpose(1, 2) @ phi + torch.diag_embed(prior)
        chol = torch.linalg.cholesky(gram)
        A = torch.cholesky_inverse(chol)
        W = torch.cholesky_solve(phi.transpose(1, 2) @ (y * m), chol)
        return W, A

    def block_bounds(self, phi: torch.Tensor, mask: torch.Tensor) -> Tuple[torch.Tensor, torch.Tensor]:
        """phi (B, K, d), mask (B, K) -> the signed-square block's smallest and largest value over the
        masked context steps, (B, n) each."""
        block = phi[..., self.ssq_start:self.ssq_stop]
        m = mask.unsqueeze(-1)
        big = torch.finfo(phi.dtype).max
        lo = torch.where(m, block, torch.full_like(block, big)).amin(1)
        hi = torch.where(m, block, torch.full_like(block, -big)).amax(1)
        return lo, hi

    def clamp_block(self, phi_t: torch.Tensor, lo: torch.Tensor, hi: torch.Tensor) -> torch.Tensor:
        """phi_t (B, d) with its signed-square block clamped to [lo, hi] (B, n)."""
        return clamp_columns(phi_t, lo, hi, self.ssq_start, self.ssq_stop)

    def read(self, phi_t: torch.Tensor, W: torch.Tensor, A: torch.Tensor) -> Tuple[torch.Tensor, torch.Tensor]:
        """phi_t (B, d) -> r (B, 6) and v (B,) = 1 + phi^T A phi."""
        r = (phi_t.unsqueeze(1) @ W).squeeze(1)
        v = 1.0 + ((phi_t.unsqueeze(1) @ A).squeeze(1) * phi_t).sum(-1)
        return r, v


class OutputHeads(nn.Module):
    """f_y, one MLP per motion dimension: (r, h, z) -> mean and bounded std."""

    def __init__(self, cfg: CchpConfig):
        super().__init__()
        self.heads = cfg.attention_heads
        in_size = MOTION_DIM + cfg.state_size + cfg.latent_dim
        self.net = PerDimensionMLP(MOTION_DIM, [in_size] + list(cfg.output_hidden) + [2])
        self.std_min = cfg.std_min
        self.read_skip = cfg.read_skip

    def forward(self, r: torch.Tensor, h: torch.Tensor, z: torch.Tensor) -> Tuple[torch.Tensor, torch.Tensor]:
        """r (B, heads, 6), h (B, H), z (B, Dz) -> mean, std (B, 6) in label-scale units."""
        b = h.shape[0]
        r = r.expand(b, MOTION_DIM, MOTION_DIM)  # one context read per output dimension
        hz = torch.cat([h, z], -1).unsqueeze(1).expand(b, MOTION_DIM, h.shape[-1] + z.shape[-1])
        out = self.net(torch.cat([r, hz], -1))  # (B, 6, 2)
        mean = out[..., 0]
        if self.read_skip:  # output dimension d adds its own read of dimension d
            mean = mean + torch.diagonal(r, dim1=1, dim2=2)
        return mean, bounded_std(out[..., 1], self.std_min)


@dataclass
class ContextEncoding:
    """What the decoder needs from a context: per-item keys, values, mask, and q(z|C)."""

    keys: torch.Tensor  # (B, heads, K, dk)
    values: torch.Tensor  # (B, K, 6), label-scale units
    mask: torch.Tensor  # (B, K) bool
    z_mu: torch.Tensor  # (B, Dz)
    z_sigma: torch.Tensor  # (B, Dz)
    # The Bayesian linear read ("bayes_linear"): W (B, d, 6) and A (B, d, d); keys then hold Phi (B, 1, K, d).
    blr_W: Optional[torch.Tensor] = None
    blr_A: Optional[torch.Tensor] = None
    blr_lo: Optional[torch.Tensor] = None  # (B, n) the signed-square block's range over the context
    blr_hi: Optional[torch.Tensor] = None  # (phi_signed_square_clamp only)


class Cchp(nn.Module):
    """The whole CCHP: encoder (recurrent encoder cells + latent encoder) and
    decoder (recurrent encoder cell + context attention + output heads)."""

    kind = "cchp"

    def __init__(self, cfg: Optional[CchpConfig] = None):
        super().__init__()
        self.cfg = cfg or CchpConfig()
        if self.cfg.attention_heads not in (1, MOTION_DIM):
            raise ValueError(f"attention_heads must be 1 or {MOTION_DIM}, got {self.cfg.attention_heads}")
        if self.cfg.attention_kernel not in ("dot", "distance"):
            raise ValueError(f"attention_kernel must be 'dot' or 'distance', got {self.cfg.attention_kernel!r}")
        if self.cfg.key_source not in ("state", "gesture"):
            raise ValueError(f"key_source must be 'state' or 'gesture', got {self.cfg.key_source!r}")
        if self.cfg.read not in ("attention", "bayes_linear"):
            raise ValueError(f"read must be 'attention' or 'bayes_linear', got {self.cfg.read!r}")
        if self.cfg.read == "bayes_linear" and (self.cfg.key_source != "gesture" or self.cfg.attention_heads != 1):
            raise ValueError("read 'bayes_linear' needs key_source 'gesture' and one attention head")
        if self.cfg.label_lead < 0 or (self.cfg.label_lead > 0 and self.cfg.read != "bayes_linear"):
            raise ValueError("label_lead must be >= 0, and > 0 needs read 'bayes_linear'")
        if self.cfg.phi_signed_square and not (self.cfg.read == "bayes_linear" and self.cfg.phi_window > 0):
            raise ValueError("phi_signed_square needs read 'bayes_linear' and phi_window > 0")
        if self.cfg.phi_signed_square_clamp and not self.cfg.phi_signed_square:
            raise ValueError("phi_signed_square_clamp needs phi_signed_square")
        self.normalizer = Normalizer()
        self.cell = EncoderCell(self.cfg)
        self.latent = LatentEncoder(self.cfg)
        self.attention = ContextAttention(self.cfg)
        self.output = OutputHeads(self.cfg)
        self.blr = BayesLinearRead(self.cfg) if self.cfg.read == "bayes_linear" else None

    # -- encoder ---------------------------------------------------------
    def encode_sequences(self, x: torch.Tensor, y: torch.Tensor) -> torch.Tensor:
        """Hidden states of sequences with their own labels fed back.

        x (N, T, 36), y (N, T, 6), both normalised; returns h (N, T, H).
        Steps past a sequence's end are computed but meaningless (masked later).
        """
        n, t_len, _ = x.shape
        fingers = self.cell.fingers(x)
        y_prev = torch.cat([y.new_zeros(n, 1, MOTION_DIM), y[:, :-1]], 1)
        h = x.new_zeros(n, self.cfg.state_size)
        c = x.new_zeros(n, self.cfg.state_size)
        hs = []
        for t in range(t_len):
            h, c = self.cell(fingers[:, t], y_prev[:, t], h, c)
            hs.append(h)
        return torch.stack(hs, 1)

    def encode_context(
        self, batch: Batch, h_c: Optional[torch.Tensor] = None
    ) -> Tuple[ContextEncoding, torch.Tensor]:
        """Encode every context piece of the batch (h_c (B*P, Tc, H) if already
        computed). Returns the encoding and the summed f_a features with their
        step counts (to extend to q(z|C,T))."""
        b, p, tc, _ = batch.x_c.shape
        y_c = self.normalizer_y(batch.y_c).reshape(b * p, tc, MOTION_DIM)
        if h_c is None:
            x_c = self.normalizer_x(batch.x_c).reshape(b * p, tc, FEATURE_DIM)
            h_c = self.encode_sequences(x_c, y_c)
        mask = batch.mask_c.reshape(b, p * tc)
        values = lead_labels(y_c, batch.mask_c.reshape(b * p, tc), self.cfg.label_lead).reshape(b, p * tc, MOTION_DIM)
        blr_W = blr_A = blr_lo = blr_hi = None
        if self.blr is not None:
            x_pieces = self.normalizer_x(batch.x_c).reshape(b * p, tc, FEATURE_DIM)
            win = self.blr.windows(x_pieces)  # per piece: each piece starts from zeros
            x_n = x_pieces.reshape(b, p * tc, FEATURE_DIM)
            phi = self.blr.features(h_c.reshape(b, p * tc, -1)[..., self.cfg.hidden_size:], x_n,
                                    None if win is None else win.reshape(b, p * tc, -1))
            blr_W, blr_A = self.blr.fit(phi, values, mask)
            if self.blr.clamp:
                blr_lo, blr_hi = self.blr.block_bounds(phi, mask)
            keys = phi.unsqueeze(1)
        else:
            keys = self.attention.project_keys(h_c.reshape(b, p * tc, -1))
        feats = self.latent.step_features(h_c, y_c).reshape(b, p * tc, -1)
        m = mask.unsqueeze(-1).to(feats.dtype)
        sums = (feats * m).sum(1)
        counts = m.sum(1)
        z_mu, z_sigma = self.latent.from_summary(sums / counts.clamp_min(1.0))
        return (ContextEncoding(keys, values, mask, z_mu, z_sigma, blr_W, blr_A, blr_lo, blr_hi),
                torch.cat([sums, counts], -1))

    def encode_context_and_target(self, batch: Batch) -> Tuple[torch.Tensor, torch.Tensor]:
        """Hidden states of the context pieces (B*P, Tc, H) and of the targets
        (B, T, H) with their own labels fed back, in one recurrent pass."""
        b, p, tc, _ = batch.x_c.shape
        t_len = batch.x.shape[1]
        n_max = max(tc, t_len)

        def pad(a: torch.Tensor) -> torch.Tensor:
            return nn.functional.pad(a, (0, 0, 0, n_max - a.shape[1]))

        x = torch.cat([pad(batch.x_c.reshape(b * p, tc, FEATURE_DIM)), pad(batch.x)], 0)
        y = torch.cat([pad(batch.y_c.reshape(b * p, tc, MOTION_DIM)), pad(batch.y)], 0)
        h = self.encode_sequences(self.normalizer_x(x), self.normalizer_y(y))
        return h[: b * p, :tc], h[b * p :, :t_len]

    def posterior(
        self, batch: Batch, context_stats: torch.Tensor, h_t: Optional[torch.Tensor] = None
    ) -> Tuple[torch.Tensor, torch.Tensor]:
        """q(z | C, T): the latent encoder over the context and target steps."""
        y = self.normalizer_y(batch.y)
        if h_t is None:
            h_t = self.encode_sequences(self.normalizer_x(batch.x), y)
        feats = self.latent.step_features(h_t, y)
        m = batch.mask.unsqueeze(-1).to(feats.dtype)
        sums = context_stats[:, :-1] + (feats * m).sum(1)
        counts = context_stats[:, -1:] + m.sum(1)
        return self.latent.from_summary(sums / counts.clamp_min(1.0))

    # -- decoder ---------------------------------------------------------
    def decode(
        self,
        x: torch.Tensor,
        ctx: ContextEncoding,
        z: torch.Tensor,
        y_teacher: Optional[torch.Tensor] = None,
        p_tf: float = 0.0,
        generator: Optional[torch.Generator] = None,
        keep_attention: bool = False,
        readouts: Optional[List[torch.Tensor]] = None,
    ) -> Tuple[torch.Tensor, torch.Tensor, Optional[torch.Tensor]]:
        """Run the decoder cell over the target.

        x (B, T, 36) normalised; y_teacher (B, T, 6) normalised ground truth.
        The previous output fed back is the ground truth with probability p_tf
        (per item and step), otherwise the model's own mean (detached).
        Returns mean, std (B, T, 6) in label-scale units and optionally the
        attention weights (B, T, heads, K). If `readouts` is a list, each
        step's context read r(t) (B, heads, 6), label-scale units, is appended.
        """
        b, t_len, _ = x.shape
        fingers = self.cell.fingers(x)
        h = x.new_zeros(b, self.cfg.state_size)
        c = x.new_zeros(b, self.cfg.state_size)
        y_prev = x.new_zeros(b, MOTION_DIM)
        means, stds, attns = [], [], []
        win = self.blr.windows(x) if self.blr is not None else None
        for t in range(t_len):
            h, c = self.cell(fingers[:, t], y_prev, h, c)
            if self.blr is not None:
                phi_t = self.blr.features(h[:, self.cfg.hidden_size:], x[:, t], None if win is None else win[:, t])
                if ctx.blr_lo is not None:
                    phi_t = self.blr.clamp_block(phi_t, ctx.blr_lo, ctx.blr_hi)
                r, v = self.blr.read(phi_t, ctx.blr_W, ctx.blr_A)
                r = r.unsqueeze(1)  # (B, 1, 6): one read
                if keep_attention:  # the equivalent kernel a = phi^T A Phi^T, masked
                    a = ((phi_t.unsqueeze(1) @ ctx.blr_A) @ ctx.keys[:, 0].transpose(1, 2)).squeeze(1)
                    weights = (a * ctx.mask.to(a.dtype)).unsqueeze(1)
                else:
                    weights = r
            else:
                r, weights = self.attention(h, ctx.keys, ctx.values, ctx.mask)
                v = None
            if readouts is not None:
                readouts.append(r)
            mean, std = self.output(r, h, z)
            if v is not None:  # the posterior's predictive spread: wider for a gesture unlike the context
                std = std * v.sqrt().unsqueeze(-1)
            means.append(mean)
            stds.append(std)
            if keep_attention:
                attns.append(weights)
            if y_teacher is None or p_tf <= 0.0:
                y_prev = mean.detach()
            elif p_tf >= 1.0:
                y_prev = y_teacher[:, t]
            else:
                use_truth = torch.rand(b, 1, generator=generator, device=x.device) < p_tf
                y_prev = torch.where(use_truth, y_teacher[:, t], mean.detach())
        attention = torch.stack(attns, 1) if keep_attention else None
        return torch.stack(means, 1), torch.stack(stds, 1), attention

    def normalizer_x(self, x: torch.Tensor) -> torch.Tensor:
        return x / self.normalizer.feature_scale

    def normalizer_y(self, y: torch.Tensor) -> torch.Tensor:
        return y / self.normalizer.label_scale

    def forward(
        self,
        batch: Batch,
        p_tf: float = 0.0,
        sample_posterior: bool = True,
        generator: Optional[torch.Generator] = None,
        x_noise_std: float = 0.0,
        nll_beta: float = 0.0,
        readout_weight: float = 0.0,
    ) -> Dict[str, torch.Tensor]:
        """The ELBO terms for a batch (see `cchp_elbo`)."""
        return cchp_elbo(self, batch, p_tf, sample_posterior, generator, x_noise_std, nll_beta, readout_weight)

    @torch.no_grad()
    def predict(
        self, batch: Batch, z_from: str = "prior_mean", generator: Optional[torch.Generator] = None,
        keep_attention: bool = False,
    ) -> Dict[str, torch.Tensor]:
        """Free-running prediction (the model's own mean fed back), physical units."""
        ctx, _ = self.encode_context(batch)
        if z_from == "prior_mean":
            z = ctx.z_mu
        elif z_from == "prior_sample":
            z = ctx.z_mu + ctx.z_sigma * torch.randn(ctx.z_mu.shape, generator=generator, device=ctx.z_mu.device)
        else:
            raise ValueError(f"unknown z_from {z_from!r}")
        mean, std, attn = self.decode(self.normalizer_x(batch.x), ctx, z, keep_attention=keep_attention)
        scale = self.normalizer.label_scale
        out = {"mean": mean * scale, "std": std * scale}
        if attn is not None:
            out["attention"] = attn
        return out


def cchp_elbo(
    model: Cchp,
    batch: Batch,
    p_tf: float,
    sample_posterior: bool = True,
    generator: Optional[torch.Generator] = None,
    x_noise_std: float = 0.0,
    nll_beta: float = 0.0,
    readout_weight: float = 0.0,
) -> Dict[str, torch.Tensor]:
    """Negative ELBO per target clip, averaged over the batch.

    ELBO = sum_t E_{z ~ q(z|C,T)} log N(y_T(t); mu(t), sigma(t)) - KL(q(z|C,T) || q(z|C))
    (paper, eq. "elbo_2"), one z sample per clip. The log-likelihood is taken
    in physical units, so values compare across models with the same data.
    `x_noise_std` adds Gaussian noise (in physical units) to the target input.
    `readout_weight` > 0 adds to the training loss that many times
    0.5 * sum_t |r(t) - y(t)|^2 (label-scale units, per clip): the context read
    itself should predict the twist. This trains the attention to find the
    context steps with the same gesture directly, instead of only through the
    output heads, which early in training learn to ignore an uninformative read.
    Returns loss (the training objective), elbo_loss (= -ELBO), nll, kl, mse of
    the mean (per step and dimension) and, with a readout weight, readout_mse.
    """
    h_c, h_t = model.encode_context_and_target(batch)
    ctx, stats = model.encode_context(batch, h_c)
    post_mu, post_sigma = model.posterior(batch, stats, h_t)
    if sample_posterior:
        eps = torch.randn(post_mu.shape, generator=generator, device=post_mu.device)
        z = post_mu + post_sigma * eps
    else:
        z = post_mu
    x = batch.x
    if x_noise_std > 0.0:
        x = x + x_noise_std * torch.randn(x.shape, generator=generator, device=x.device)
    if model.cfg.label_lead > 0:  # the decoder is trained to say what the labels will say label_lead steps on
        batch = Batch(batch.x, lead_labels(batch.y, batch.mask, model.cfg.label_lead), batch.mask, batch.x_c,
                      batch.y_c, batch.mask_c)
    y_n = model.normalizer_y(batch.y)
    reads: Optional[List[torch.Tensor]] = [] if readout_weight > 0.0 else None
    mean_n, std_n, _ = model.decode(model.normalizer_x(x), ctx, z, y_teacher=y_n, p_tf=p_tf, generator=generator,
                                    readouts=reads)
    scale = model.normalizer.label_scale
    kl = gaussian_kl(post_mu, post_sigma, ctx.z_mu, ctx.z_sigma)
    terms = likelihood_terms(batch, mean_n * scale, std_n * scale, kl, scale, nll_beta)
    if reads is not None:
        r = torch.stack(reads, 1)  # (B, T, heads, 6)
        # One head: its read of every dimension; one head per dimension: head d's read of dimension d.
        r = r[:, :, 0] if r.shape[2] == 1 else torch.diagonal(r, dim1=2, dim2=3)
        m = batch.mask.to(r.dtype)
        sq = ((r - y_n) ** 2).sum(-1) * m  # (B, T)
        terms["loss"] = terms["loss"] + readout_weight * 0.5 * sq.sum(1).mean()
        terms["readout_mse"] = sq.sum() / (m.sum().clamp_min(1.0) * MOTION_DIM)
    return terms


def likelihood_terms(
    batch: Batch, mean: torch.Tensor, std: torch.Tensor, kl: Optional[torch.Tensor],
    label_scale: Optional[torch.Tensor] = None, nll_beta: float = 0.0,
) -> Dict[str, torch.Tensor]:
    """Per-batch loss terms from predicted means/stds (B, T, 6) in physical units.

    "loss" is the training objective: -ELBO, or with nll_beta > 0 the beta-NLL
    of Seitzer et al. (ICLR 2022), where each step's and dimension's NLL is
    weighted by the (gradient-free) predicted variance in label-scale units to
    the power beta. Plain NLL lets a large predicted std starve the mean of
    gradient, which slows the fit of the mean a lot. "elbo_loss" (and
    "loss_per_clip") are always the plain -ELBO.
    """
    m = batch.mask.to(mean.dtype)
    nll_e = -gaussian_log_prob(batch.y, mean, std)  # (B, T, 6)
    nll = (nll_e.sum(-1) * m).sum(1)  # (B,)
    sq = (((batch.y - mean) ** 2).mean(-1) * m).sum(1)  # (B,)
    steps = m.sum(1).clamp_min(1.0)
    kl_b = kl if kl is not None else torch.zeros_like(nll)
    if nll_beta > 0.0:
        std_n = std.detach() if label_scale is None else std.detach() / label_scale
        weighted = ((nll_e * std_n.pow(2.0 * nll_beta)).sum(-1) * m).sum(1)
        objective = (weighted + kl_b).mean()
    else:
        objective = (nll + kl_b).mean()
    return {
        "loss": objective,
        "elbo_loss": (nll + kl_b).mean(),
        "nll": nll.mean(),
        "kl": kl_b.mean(),
        "mse": (sq / steps).mean(),
        "loss_per_clip": (nll + kl_b).detach(),
        "mse_per_clip": (sq / steps).detach(),
    }
