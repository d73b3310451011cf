"""experiments/sweep_decodability.py: the feature sets it compares see what they are meant to."""

import numpy as np

from rtcohand_drake.data.hand_features import hand_features
from rtcohand_drake.data.population.hand_model import hand_keypoints_local

SCRIPT = "experiments/sweep_decodability.py"


def _rotations(rotvecs):
    """Rotation matrices (N, 3, 3) of rotation vectors (N, 3) (Rodrigues)."""
    out = []
    for r in rotvecs:
        theta = np.linalg.norm(r)
        k = r / theta if theta > 0 else np.zeros(3)
        K = np.array([[0, -k[2], k[1]], [k[2], 0, -k[0]], [-k[1], k[0], 0]])
        out.append(np.eye(3) + np.sin(theta) * K + (1 - np.cos(theta)) * K @ K)
    return np.array(out)


def _hand(n, abduction=0.0):
    """n frames of a relaxed hand (keypoints in its own frame), the fingers' abduction per frame."""
    curl = np.full((n, 4), 0.3)
    ab = np.broadcast_to(np.asarray(abduction, float).reshape(-1, 1), (n, 4))
    thumb = np.tile(np.deg2rad([40.0, 20.0, 15.0, 10.0]), (n, 1))
    return hand_keypoints_local(curl, ab, thumb, 1.0)


def test_a_rigid_hand_moving_and_turning_shows_no_articulation(load_script):
    m = load_script(SCRIPT)
    fps, n = 30.0, 60
    t = np.arange(n) / fps
    shift = np.outer(0.1 * t, [1.0, -0.5, 0.2])[:, None, :]
    R = _rotations(np.outer(0.8 * t, [0.3, 0.2, 0.93]))
    moving = _hand(n) + shift
    turning = np.einsum("tij,tkj->tki", R, _hand(n)) + shift
    for kp, turns in ((moving, False), (turning, True)):
        x, _ = hand_features(kp, fps)
        assert np.abs(x).max() > 0.05  # the hand does move
        u = m.frame_features(x.astype(np.float64), "x, x|x|, u, u|u|")[:, 72:102].reshape(-1, 5, 6)
        # Relative to the palm the fingers do not turn; nor move, unless the hand turns (w x r).
        assert np.abs(u[2:, :, 3:]).max() < 1e-4
        assert (np.abs(u[2:, :, :3]).max() > 1e-3) == turns
        if not turns:
            assert np.abs(u[2:]).max() < 1e-4
        tips = m.fingertip_velocities(kp, fps, None)
        assert tips.shape == (len(x), 15) and np.abs(tips[1:]).max() < 1e-6  # still in the palm's frame


def test_a_spread_shows_in_the_fingertips_and_its_sign_follows_the_spread(load_script):
    m = load_script(SCRIPT)
    fps, n = 30.0, 31
    ramp = np.linspace(0.0, 0.2, n)
    # Sideways (the palm's x) velocity of the index, middle and ring tips, for a spread each way.
    side = [m.fingertip_velocities(_hand(n, sign * ramp), fps, None)[1:].reshape(-1, 5, 3)[:, 1:4, 0]
            for sign in (1, -1)]
    assert np.abs(side[0]).min() > 0.01
    assert (np.sign(side[0]) == -np.sign(side[1])).all()
    tips = m.fingertip_velocities(_hand(n, ramp), fps, None)
    np.testing.assert_allclose(m.frame_features(tips, "tips t, t|t|")[:, 15:], tips * np.abs(tips))
