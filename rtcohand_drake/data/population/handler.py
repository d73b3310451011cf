"""The human handler: labels that follow a gesture late, smoothed and misjudged, and the object pose they integrate."""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

if TYPE_CHECKING:
    from rtcohand_drake.data.population.config import GeneratorConfig
    from rtcohand_drake.data.population.people import UserProfile

def handler_labels(
    config: GeneratorConfig,
    user: UserProfile,
    motions: tuple[tuple[int, int], ...],
    envelopes: list[np.ndarray],
    intensity: float,
    t: np.ndarray,
    rng: np.random.Generator,
) -> tuple[np.ndarray, np.ndarray]:
    """Object velocity (N, 6) a handler produces for the gesture, and their intent (N, 6)."""
    N = t.size
    dt = float(t[1] - t[0]) if N > 1 else 1.0 / config.fps
    delay = float(rng.uniform(*config.handler_delay_s))
    lag = float(rng.uniform(*config.handler_lag_s))
    intent = np.zeros((N, 6))
    for (dim, sign), env in zip(motions, envelopes):
        magnitude = (
            user.handler_magnitude[dim]
            * intensity**config.handler_follow_exponent
            * float(np.exp(rng.normal(0.0, config.handler_misjudge_log_sd)))
        )
        intent[:, dim] += sign * magnitude * env
    delayed = np.zeros_like(intent)
    for dim in range(6):
        delayed[:, dim] = np.interp(t - delay, t, intent[:, dim], left=0.0)
    # First-order lag as a causal convolution with an exponential kernel.
    tk = np.arange(int(np.ceil(6 * lag / dt)) + 1) * dt
    kernel = np.exp(-tk / lag)
    kernel /= kernel.sum()
    smooth = np.stack([np.convolve(delayed[:, d], kernel)[:N] for d in range(6)], axis=1)
    active = sorted({d for d, _ in motions})
    leak = np.zeros((6, 6))
    for d in active:
        for j in range(6):
            if j not in active:
                leak[d, j] = rng.normal(0.0, config.handler_crosstalk) * user.handler_magnitude[j] / user.handler_magnitude[d]
    smooth = smooth + smooth @ leak
    noise_sd = np.array([config.tracking_noise_m_s] * 3 + [config.tracking_noise_rad_s] * 3)
    noise = rng.normal(0.0, 1.0, size=(N, 6)) * noise_sd
    noise = 0.5 * (noise + np.vstack([noise[:1], noise[:-1]]))  # marker filter: a little smoothing
    return smooth + noise, intent


def integrate_pose(start: np.ndarray, velocity: np.ndarray, dt: float) -> np.ndarray:
    """Poses (N, 7) [x y z qw qx qy qz] from a start position and twists in U (identity start rotation).

    The angular velocity is spatial (expressed in U), so each step left-multiplies
    the orientation: q_{k+1} = exp(w_k dt / 2) q_k, computed as a parallel prefix product.
    """
    N = velocity.shape[0]
    pos = start + np.vstack([np.zeros((1, 3)), np.cumsum(velocity[:-1, :3], axis=0) * dt])
    half = 0.5 * velocity[:-1, 3:] * dt
    th = np.linalg.norm(half, axis=1)
    dq = np.concatenate([np.cos(th)[:, None], np.sinc(th / np.pi)[:, None] * half], axis=1)
    q = np.vstack([[1.0, 0.0, 0.0, 0.0], dq])  # q[k] = step into frame k
    off = 1
    while off < N:
        q[off:] = quat_multiply(q[off:], q[:-off])
        off *= 2
    q /= np.linalg.norm(q, axis=1, keepdims=True)
    return np.hstack([pos, q])


def quat_multiply(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Hamilton product of quaternion arrays [w x y z] (..., 4)."""
    aw, ax, ay, az = np.moveaxis(a, -1, 0)
    bw, bx, by, bz = np.moveaxis(b, -1, 0)
    return np.stack(
        [
            aw * bw - ax * bx - ay * by - az * bz,
            aw * bx + ax * bw + ay * bz - az * by,
            aw * by - ax * bz + ay * bw + az * bx,
            aw * bz + ax * by - ay * bx + az * bw,
        ],
        axis=-1,
    )
