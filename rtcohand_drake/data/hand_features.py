"""Hand features: 21 hand keypoints at any frame rate -> x(t) in R^36 at the policy rate.

The policy sees, for each of six hand parts (palm, thumb, index, middle, ring,
pinky, in that order), the linear and angular velocity of a frame attached to
that part, expressed in the user frame U (X right, Y forward, Z up; see
docs/interfaces.md (frames and the meaning of a twist)). The vector is part-major::

    x[6p : 6p+3]   = v_p   linear velocity of part p's frame origin, m/s, in U
    x[6p+3 : 6p+6] = w_p   angular velocity of part p's frame, rad/s, in U

Keypoints follow the 21-point order of MediaPipe/OpenPose: 0 wrist; thumb
1 CMC, 2 MCP, 3 IP, 4 tip; index 5 MCP .. 8 tip; middle 9-12; ring 13-16;
pinky 17-20.

Part frames (rotation R = [e_x e_y e_z] with unit columns, origin o)
----------------------------------------------------------------------
Palm.  ``along = k9 - k0`` (wrist to middle MCP), ``across = k5 - k17``
(pinky MCP to index MCP)::

    e_y = along / |along|
    e_z = (across x along) / |across x along|      palm normal
    e_x = e_y x e_z
    o   = mean(k0, k5, k9, k13, k17)

For a right hand held palm down with the fingers pointing forward, e_y = +Y,
e_z = -Z (out of the palm) and e_x = -X (toward the thumb).

Fingers.  The chain is (base, .., tip) = (1, 2, 3, 4) for the thumb and
(MCP, PIP, DIP, tip) for the others; ``d = tip - base``::

    e_y = d / |d|
    index..pinky: e_x = unit(a - (a . e_y) e_y) with a = palm e_x,  e_z = e_x x e_y
    thumb:        e_z = unit(n - (n . e_y) e_y) with n = palm e_z,  e_x = e_y x e_z
    o   = mean of the chain's four keypoints

The reference axis is the one the part's base-to-tip direction never lines up
with over its range of motion: a finger flexes about the palm's across axis,
so its direction sweeps through the palm normal when it curls (the normal
would be a degenerate reference there); the thumb swings across the palm, so
its direction can line up with the across axis but not with the normal.

Velocities from two poses
-------------------------
For poses (R0, o0) at time t0 and (R1, o1) at t1 = t0 + dt::

    v = (o1 - o0) / dt
    w = log(R1 R0^T)^vee / dt

``log`` is the SO(3) logarithm: with s = vee((R - R^T) / 2) = sin(theta) u and
cos(theta) = (trace R - 1) / 2, theta = atan2(|s|, cos(theta)) and
log(R)^vee = theta u = s * theta / sin(theta). Since R1 = exp(dt [w]) R0 for a
constant spatial angular velocity w, this recovers w exactly (for
|w| dt < pi), expressed in U. v is the mean velocity of the origin over the
interval (a chord, for a rotating part).

Resampling to the policy rate (explicit)
----------------------------------------
Frame times are ``timestamps`` when given, else i / fps. Policy sample times
are t_k = t_first + k / rate_hz for k = 0 .. floor((t_last - t_first) * rate_hz).
The keypoints at t_k are interpolated linearly between the two recorded
frames around t_k that saw the hand, when those two frames are at most
``max(max_gap_s, 1.5 / fps)`` apart (a short dropout is bridged; at low frame
rates no missing frame is bridged); a sample that falls on a frame uses that
frame. Part poses are computed at every t_k, and

    x(t_k) = velocity between the poses at t_{k-1} and t_k        (k >= 1)

which is causal and equals the average of the part velocity over the last
policy period (a moving average followed by downsampling). x(t_0) = 0: the
first sample has no predecessor and reads as rest (clips start at rest).

Lost hand
---------
valid[k] is False when the pose at t_k, or at t_{k-1}, could not be formed
(no usable frames around it, or a degenerate hand); such a feature is all
zeros, never NaN. valid[0] says whether the hand was seen at t_0.

Labels and other signals are resampled with :func:`resample` (linear
interpolation at the same t_k).
"""

from __future__ import annotations

import numpy as np

PARTS = ("palm", "thumb", "index", "middle", "ring", "pinky")
PART_DIM = 6  # a part's linear and angular velocity
# The one definition of the feature size: the ports, the networks and the references import it.
FEATURE_DIM = len(PARTS) * PART_DIM
NUM_KEYPOINTS = 21

# Keypoint chains (base .. tip) of the five fingers, in PARTS order after the palm.
FINGER_CHAINS = np.array(
    [[1, 2, 3, 4], [5, 6, 7, 8], [9, 10, 11, 12], [13, 14, 15, 16], [17, 18, 19, 20]]
)
PALM_POINTS = np.array([0, 5, 9, 13, 17])

# Default largest gap between two seen frames that interpolation bridges.
DEFAULT_MAX_GAP_S = 0.1
_TIME_TOL_S = 1e-6


def _unit(v: np.ndarray) -> np.ndarray:
    n = np.linalg.norm(v, axis=-1, keepdims=True)
    with np.errstate(invalid="ignore", divide="ignore"):
        return v / n


def _cross(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """np.cross of (..., 3) arrays, the same products and differences, without its axis handling
    (the live source calls `part_frames` on one hand at a time)."""
    out = np.empty(np.broadcast_shapes(a.shape, b.shape))
    out[..., 0] = a[..., 1] * b[..., 2] - a[..., 2] * b[..., 1]
    out[..., 1] = a[..., 2] * b[..., 0] - a[..., 0] * b[..., 2]
    out[..., 2] = a[..., 0] * b[..., 1] - a[..., 1] * b[..., 0]
    return out


def part_frames(keypoints: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Part frames of hands given as keypoints (..., 21, 3), metres, in U.

    Returns (R, o): rotations (..., 6, 3, 3) whose columns are the part axes
    e_x, e_y, e_z expressed in U, and origins (..., 6, 3). A degenerate or
    missing hand gives NaN entries.
    """
    kp = np.asarray(keypoints, dtype=np.float64)
    if kp.shape[-2:] != (NUM_KEYPOINTS, 3):
        raise ValueError(f"keypoints must have shape (..., 21, 3), got {kp.shape}")
    lead = kp.shape[:-2]
    R = np.empty(lead + (6, 3, 3))
    o = np.empty(lead + (6, 3))

    along = kp[..., 9, :] - kp[..., 0, :]
    across = kp[..., 5, :] - kp[..., 17, :]
    py = _unit(along)
    pz = _unit(_cross(across, along))
    px = _cross(py, pz)
    R[..., 0, :, 0] = px
    R[..., 0, :, 1] = py
    R[..., 0, :, 2] = pz
    o[..., 0, :] = kp[..., PALM_POINTS, :].mean(axis=-2)

    chains = kp[..., FINGER_CHAINS, :]  # (..., 5, 4, 3)
    fy = _unit(chains[..., 3, :] - chains[..., 0, :])  # (..., 5, 3)
    # Thumb: palm normal as reference.
    n = pz
    ty = fy[..., 0, :]
    tz = _unit(n - np.sum(n * ty, axis=-1, keepdims=True) * ty)
    tx = _cross(ty, tz)
    # Index..pinky: palm across axis as reference.
    a = px[..., None, :]
    gy = fy[..., 1:, :]
    gx = _unit(a - np.sum(a * gy, axis=-1, keepdims=True) * gy)
    gz = _cross(gx, gy)
    R[..., 1, :, 0] = tx
    R[..., 1, :, 1] = ty
    R[..., 1, :, 2] = tz
    R[..., 2:, :, 0] = gx
    R[..., 2:, :, 1] = gy
    R[..., 2:, :, 2] = gz
    o[..., 1:, :] = chains.mean(axis=-2)
    return R, o


def rotation_log(R: np.ndarray) -> np.ndarray:
    """Rotation vectors theta * u (..., 3) of rotation matrices (..., 3, 3); |theta| < pi."""
    s = 0.5 * np.stack(
        [R[..., 2, 1] - R[..., 1, 2], R[..., 0, 2] - R[..., 2, 0], R[..., 1, 0] - R[..., 0, 1]],
        axis=-1,
    )
    c = 0.5 * (np.trace(R, axis1=-2, axis2=-1) - 1.0)
    sn = np.linalg.norm(s, axis=-1)
    theta = np.arctan2(sn, c)
    with np.errstate(invalid="ignore", divide="ignore"):
        scale = np.where(sn > 1e-12, theta / np.where(sn > 1e-12, sn, 1.0), 1.0)
    return s * scale[..., None]


def part_velocities(
    R0: np.ndarray, o0: np.ndarray, R1: np.ndarray, o1: np.ndarray, dt: float | np.ndarray
) -> np.ndarray:
    """Feature vectors (..., 36) from two consecutive part poses dt seconds apart.

    R0, R1: (..., 6, 3, 3); o0, o1: (..., 6, 3), as from :func:`part_frames`.
    Non-finite inputs give non-finite outputs; :func:`hand_features` and
    :class:`HandFeatureStream` turn those into zeros with a false flag.
    """
    dt = np.asarray(dt, dtype=np.float64)
    dt_b = dt[..., None, None] if dt.ndim else dt
    v = (o1 - o0) / dt_b
    w = rotation_log(R1 @ np.swapaxes(R0, -1, -2)) / dt_b
    x = np.concatenate([v, w], axis=-1)  # (..., 6, 6)
    return x.reshape(x.shape[:-2] + (FEATURE_DIM,))


def frame_times(n_frames: int, fps: float, timestamps: np.ndarray | None = None) -> np.ndarray:
    """Times (n,) of recorded frames: ``timestamps`` when given, else i / fps."""
    if timestamps is not None:
        t = np.asarray(timestamps, dtype=np.float64)
        if t.shape != (n_frames,):
            raise ValueError(f"timestamps must have shape ({n_frames},), got {t.shape}")
        return t
    if not fps > 0:
        raise ValueError(f"fps must be positive, got {fps}")
    return np.arange(n_frames, dtype=np.float64) / float(fps)


def policy_times(times: np.ndarray, rate_hz: float) -> np.ndarray:
    """Policy sample times t_k = t_first + k / rate_hz up to the last frame time."""
    if not rate_hz > 0:
        raise ValueError(f"rate_hz must be positive, got {rate_hz}")
    times = np.asarray(times, dtype=np.float64)
    if times.size == 0:
        return np.zeros(0)
    n = int(np.floor((times[-1] - times[0]) * rate_hz + 1e-6)) + 1
    return times[0] + np.arange(n) / float(rate_hz)


def interpolate_keypoints(
    keypoints: np.ndarray, times: np.ndarray, query_times: np.ndarray, max_gap_s: float
) -> tuple[np.ndarray, np.ndarray]:
    """Keypoints (K, 21, 3) at ``query_times`` and a (K,) flag of where they are known.

    Linear interpolation between the two seen frames around each query time,
    if they are at most ``max_gap_s`` apart; a query on a seen frame takes it.
    """
    kp = np.asarray(keypoints, dtype=np.float64)
    tq = np.asarray(query_times, dtype=np.float64)
    out = np.zeros((tq.size, NUM_KEYPOINTS, 3))
    seen = np.flatnonzero(np.isfinite(kp).all(axis=(1, 2)))
    if seen.size == 0 or tq.size == 0:
        return out, np.zeros(tq.size, dtype=bool)
    tv = times[seen]
    j = np.searchsorted(tv, tq + _TIME_TOL_S, side="right") - 1
    jc = np.clip(j, 0, seen.size - 1)
    jn = np.clip(j + 1, 0, seen.size - 1)
    exact = (j >= 0) & (np.abs(tv[jc] - tq) <= _TIME_TOL_S)
    gap = tv[jn] - tv[jc]
    bridged = (j >= 0) & (j + 1 < seen.size) & (gap <= max_gap_s + _TIME_TOL_S) & ~exact
    known = exact | bridged
    w = np.where(bridged, (tq - tv[jc]) / np.where(gap > 0, gap, 1.0), 0.0)[:, None, None]
    out = (1.0 - w) * kp[seen[jc]] + w * kp[seen[jn]]
    out[~known] = 0.0
    return out, known


def hand_features(
    keypoints: np.ndarray,
    fps: float,
    rate_hz: float = 10.0,
    timestamps: np.ndarray | None = None,
    max_gap_s: float = DEFAULT_MAX_GAP_S,
) -> tuple[np.ndarray, np.ndarray]:
    """Features (T, 36) float32 and validity (T,) bool at times t_first + k / rate_hz.

    keypoints: (N, 21, 3) metres in the user frame, NaN where the hand was lost.
    See the module docstring for frames, math and resampling.
    """
    kp = np.asarray(keypoints)
    if kp.ndim != 3 or kp.shape[1:] != (NUM_KEYPOINTS, 3):
        raise ValueError(f"keypoints must have shape (N, 21, 3), got {kp.shape}")
    times = frame_times(kp.shape[0], fps, timestamps)
    tq = policy_times(times, rate_hz)
    max_gap = max(max_gap_s, 1.5 / float(fps))
    kq, known = interpolate_keypoints(kp, times, tq, max_gap)
    R, o = part_frames(kq)
    known &= np.isfinite(R).all(axis=(1, 2, 3))
    T = tq.size
    feats = np.zeros((T, FEATURE_DIM), dtype=np.float32)
    valid = np.zeros(T, dtype=bool)
    if T == 0:
        return feats, valid
    valid[0] = known[0]
    if T > 1:
        x = part_velocities(R[:-1], o[:-1], R[1:], o[1:], 1.0 / float(rate_hz))
        ok = known[:-1] & known[1:] & np.isfinite(x).all(axis=1)
        feats[1:][ok] = x[ok]
        valid[1:] = ok
    return feats, valid


def resample(
    values: np.ndarray, times: np.ndarray, rate_hz: float
) -> tuple[np.ndarray, np.ndarray]:
    """Linear interpolation of ``values`` (N, ...) at t_first + k / rate_hz.

    Returns (resampled (T, ...), new_times (T,)); the new times are those of
    :func:`policy_times`, the same as :func:`hand_features` uses, so labels and
    features line up sample for sample. Values keep their dtype class (float).
    """
    vals = np.asarray(values)
    times = np.asarray(times, dtype=np.float64)
    if vals.shape[:1] != times.shape:
        raise ValueError(f"values {vals.shape} and times {times.shape} differ in length")
    new_times = policy_times(times, rate_hz)
    flat = vals.reshape(vals.shape[0], -1).astype(np.float64)
    out = np.empty((new_times.size, flat.shape[1]))
    for c in range(flat.shape[1]):
        out[:, c] = np.interp(new_times, times, flat[:, c])
    dtype = vals.dtype if np.issubdtype(vals.dtype, np.floating) else np.float64
    return out.reshape((new_times.size,) + vals.shape[1:]).astype(dtype), new_times


def tracking_noise(keypoints: np.ndarray, window: int = 5) -> np.ndarray:
    """(N, 21, 3): each frame's offset from the centred median of `window` frames (0 at the ends):
    the tracker's jitter about the hand's smoothed path."""
    n, h = len(keypoints), window // 2
    out = np.zeros_like(keypoints)
    if n >= window:
        stack = np.stack([keypoints[i:n - window + 1 + i] for i in range(window)])
        out[h:n - h] = keypoints[h:n - h] - np.median(stack, axis=0)
    return out


def slow_noise(keypoints: np.ndarray, fps: float, window: int = 5, below_m_s: float = 0.05) -> tuple[np.ndarray, np.ndarray]:
    """(`tracking_noise` (N, 21, 3), (N,) bool: the frames whose palm centre, on its smoothed path, moves
    slower than `below_m_s`): the jitter of a hand that hardly moves."""
    noise = tracking_noise(keypoints, window)
    palm = (keypoints[:, PALM_POINTS] - noise[:, PALM_POINTS]).mean(axis=1)
    speed = np.r_[0.0, np.linalg.norm(np.diff(palm, axis=0), axis=1) * fps]
    return noise, speed < below_m_s


def join_recordings(recordings) -> list[np.ndarray]:
    """Recordings (each (N, 21, 3), NaN where the hand is lost) moved so that each starts where the
    one before ended: its first seen centre (the mean of the 21 keypoints) on the last seen centre
    of those before. Recordings played one after another then join without a jump of the hand, as a
    person's hand goes on from where it is; a recording never seen is left where it is."""
    joined, end = [], None
    for r in recordings:
        r = np.asarray(r, np.float64).reshape(len(r), NUM_KEYPOINTS, 3)
        seen = np.flatnonzero(np.isfinite(r).all(axis=(1, 2)))
        if seen.size and end is not None:
            r = r + (end - r[seen[0]].mean(axis=0))
        if seen.size:
            end = r[seen[-1]].mean(axis=0)
        joined.append(r)
    return joined


class HandFeatureStream:
    """Frame-by-frame features for a live source: call :meth:`update` at the policy rate.

    Each call takes the latest keypoints (21, 3) (NaN if the hand is lost) and
    their time, and returns (x (36,) float32, valid). The first call, and any
    call after a lost hand, returns zeros: a velocity needs two poses.
    """

    def __init__(self) -> None:
        self._prev: tuple[np.ndarray, np.ndarray, float] | None = None

    def reset(self) -> None:
        self._prev = None

    def update(self, keypoints: np.ndarray, time_s: float) -> tuple[np.ndarray, bool]:
        R, o = part_frames(np.asarray(keypoints, dtype=np.float64)[None])
        R, o = R[0], o[0]
        seen = bool(np.isfinite(R).all() and np.isfinite(o).all())
        x = np.zeros(FEATURE_DIM, dtype=np.float32)
        ok = False
        if seen and self._prev is not None:
            R0, o0, t0 = self._prev
            dt = float(time_s) - t0
            if dt > 0:
                xv = part_velocities(R0, o0, R, o, dt)
                if np.isfinite(xv).all():
                    x[:] = xv
                    ok = True
        self._prev = (R, o, float(time_s)) if seen else None
        return x, ok


# --------------------------------------------------------------------------- the hand's path and shape
#
# An extension of the input (docs/interfaces.md, the exported policy: `feature_dim` > 36), for a read
# that tells gestures apart by the posture they are made in and the path the hand took, which the 36
# velocities leave out (a one-finger gesture and the same gesture of the whole hand move alike).
# At each policy step: the 21 keypoints now and PATH_SHAPE_LAGS_S before, each about the hand's
# centre (the mean of the 21 keypoints) now, in metres in U, lag-major and row-major
# (x[63 l + 3 k + a] = keypoint k, axis a, at lag l). `median` > 1 filters each sample by the median
# of it and the samples before; the default (1) does not filter: on recorded development people a
# median of 3 or 5 policy samples read worse (docs/real_people.md). Lags reaching before the first
# sample take the first; a lost hand holds the last seen sample. The lags were chosen on recorded
# development people.
PATH_SHAPE_LAGS_S = (0.0, 0.4, 0.8, 1.2, 1.6)
PATH_SHAPE_MEDIAN = 1
PATH_SHAPE_DIM = NUM_KEYPOINTS * 3 * len(PATH_SHAPE_LAGS_S)


class PathShapeStream:
    """The hand's path and shape (PATH_SHAPE_DIM,) step by step: call :meth:`update` at the policy rate.

    `update(keypoints (21, 3), NaN when lost)` returns (x float32, seen): `seen` is False until a
    hand has been seen, and x is zeros then. Everything the stream remembers is the flat float
    vector `state` (a Drake system keeps it as discrete state): [raw samples seen, filtered samples
    seen, the newest `median` raw samples, the newest filtered samples (as many as the longest
    lag needs), oldest first].
    """

    def __init__(self, rate_hz: float = 10.0, median: int = PATH_SHAPE_MEDIAN,
                 lags_s: tuple = PATH_SHAPE_LAGS_S) -> None:
        if not rate_hz > 0 or median < 1:
            raise ValueError(f"rate_hz must be positive and median at least 1, got {rate_hz}, {median}")
        self._lags = np.array([int(round(s * rate_hz)) for s in lags_s])
        self._median = int(median)
        self._kept = int(self._lags.max()) + 1
        self._dim = NUM_KEYPOINTS * 3 * len(self._lags)
        self.state = np.zeros(2 + 63 * (self._median + self._kept))

    def reset(self) -> None:
        self.state = np.zeros_like(self.state)

    def update(self, keypoints: np.ndarray) -> tuple[np.ndarray, bool]:
        kp = np.asarray(keypoints, dtype=np.float64).reshape(-1)
        n_raw, n_kept = int(self.state[0]), int(self.state[1])
        raw = self.state[2:2 + 63 * self._median].reshape(self._median, 63)
        kept = self.state[2 + 63 * self._median:].reshape(self._kept, 63)
        if kp.size != 63:
            raise ValueError(f"keypoints must have 63 entries, got {kp.size}")
        if np.isfinite(kp).all() or n_raw:
            sample = kp if np.isfinite(kp).all() else raw[-1].copy()  # a lost hand holds the last sample
            raw[:-1] = raw[1:].copy()
            raw[-1] = sample
            n_raw = min(n_raw + 1, self._median)
        if not n_raw:
            return np.zeros(self._dim, np.float32), False
        kept[:-1] = kept[1:].copy()
        kept[-1] = np.median(raw[self._median - n_raw:], axis=0)
        n_kept = min(n_kept + 1, self._kept)
        self.state[0], self.state[1] = n_raw, n_kept
        now = kept[-1].reshape(NUM_KEYPOINTS, 3)
        centre = now.mean(axis=0)
        x = np.concatenate([(kept[self._kept - 1 - min(lag, n_kept - 1)].reshape(NUM_KEYPOINTS, 3) - centre).reshape(-1)
                            for lag in self._lags])
        return x.astype(np.float32), True


def path_shape_features(keypoints: np.ndarray, fps: float, rate_hz: float = 10.0,
                        timestamps: np.ndarray | None = None, max_gap_s: float = DEFAULT_MAX_GAP_S,
                        median: int = PATH_SHAPE_MEDIAN, lags_s: tuple = PATH_SHAPE_LAGS_S) -> np.ndarray:
    """The hand's path and shape (T, PATH_SHAPE_DIM) float32 at the sample times of :func:`hand_features`.

    The keypoints at each policy time are interpolated as there (a lost sample is held), then fed
    through a :class:`PathShapeStream`, as a live source does one step at a time.
    """
    kp = np.asarray(keypoints)
    if kp.ndim != 3 or kp.shape[1:] != (NUM_KEYPOINTS, 3):
        raise ValueError(f"keypoints must have shape (N, 21, 3), got {kp.shape}")
    times = frame_times(kp.shape[0], fps, timestamps)
    kq, known = interpolate_keypoints(kp, times, policy_times(times, rate_hz), max(max_gap_s, 1.5 / float(fps)))
    stream = PathShapeStream(rate_hz, median, lags_s)
    out = np.zeros((len(kq), NUM_KEYPOINTS * 3 * len(lags_s)), np.float32)
    for i, (k, ok) in enumerate(zip(kq, known)):
        out[i] = stream.update(k if ok else np.full((NUM_KEYPOINTS, 3), np.nan))[0]
    return out
