"""Simulated users: protocol counts, an anatomical hand, handler labels, and the need for context."""

from collections import Counter
from dataclasses import replace

import numpy as np
import pytest

from rtcohand_drake.data.dataset import to_policy_clip
from rtcohand_drake.data.population import (
    JOINT_LIMITS_DEG,
    GeneratorConfig,
    context_need_ratio,
    generate_population,
    make_user,
    simulate_user,
    user_groups,
)
from rtcohand_drake.data.hand_features import FINGER_CHAINS

CONFIG = GeneratorConfig()


@pytest.fixture(scope="module")
def user0():
    return simulate_user(CONFIG, 0, "in-sample", seed=11)


def test_user_groups_follow_paper():
    assert Counter(user_groups(15, CONFIG)) == {"in-sample": 10, "out-sample": 5}
    assert user_groups(1, CONFIG) == ["in-sample"]


def test_split_counts_as_in_paper_appendix(user0):
    _, clips, _ = user0
    assert len(clips) == 72
    one = [c for c in clips if c.active_dims.size == 1]
    two = [c for c in clips if c.active_dims.size == 2]
    assert len(one) == 24 and len(two) == 48
    assert Counter(c.split for c in clips) == {"train": 36, "test": 36}
    assert Counter(c.split for c in one) == {"train": 12, "test": 12}
    assert Counter(c.split for c in two) == {"train": 24, "test": 24}
    # Single-dimension clips: each of the 12 (dim, sign) motions twice, once per split.
    motions = Counter((c.clip_id.split("_")[1], c.split) for c in one)
    assert len(motions) == 24 and set(motions.values()) == {1}
    # Half of the test two-dimension clips use dimension pairs also seen in train.
    train_pairs = {tuple(c.active_dims) for c in two if c.split == "train"}
    test_two = [c for c in two if c.split == "test"]
    assert sum(tuple(c.active_dims) in train_pairs for c in test_two) == 12
    assert len({tuple(c.active_dims) for c in two}) == 15


def test_out_sample_user_is_all_test():
    _, clips, _ = simulate_user(CONFIG, 12, "out-sample", seed=11)
    assert len(clips) == 72 and {c.split for c in clips} == {"test"} and {c.group for c in clips} == {"out-sample"}


def test_clip_lengths_and_label_magnitudes(user0):
    _, clips, _ = user0
    for c in clips:
        assert c.num_frames / c.fps <= 5.0 and c.num_frames / c.fps >= 3.0
        v = c.object_velocity
        assert np.isfinite(v).all()
        assert np.abs(v[:, :3]).max() < 0.3 and np.abs(v[:, 3:]).max() < 1.5
        # The active dimensions carry the motion.
        peak = np.abs(v).max(axis=0) / np.array([0.1, 0.1, 0.1, 0.5, 0.5, 0.5])  # in nominal units
        assert peak[c.active_dims].min() > 2 * np.delete(peak, c.active_dims).max()
        # Every clip starts and ends at rest.
        assert np.abs(v[0]).max() < 0.05 and np.abs(v[-1, :3]).max() < 0.03


def test_handler_reacts_with_delay(user0):
    _, clips, truths = user0
    delays = []
    for c, tr in zip(clips, truths):
        d = c.active_dims[0]
        dt = 1 / c.fps
        intent = np.abs(tr.intent[:, d])
        label = np.abs(c.object_velocity[:, d])
        half = 0.5 * intent.max()
        t_int = np.argmax(intent > half) * dt
        t_lab = np.argmax(label > 0.5 * label.max()) * dt
        delays.append(t_lab - t_int)
    delays = np.array(delays)
    # Reaction delay 150-350 ms plus the smoothing lag.
    assert 0.15 < np.median(delays) < 0.8 and delays.min() > 0.05


def test_hand_is_anatomical(user0):
    user, clips, truths = user0
    bones = [(0, int(ch[0])) for ch in FINGER_CHAINS] + [
        (int(ch[i]), int(ch[i + 1])) for ch in FINGER_CHAINS for i in range(3)
    ]
    first_lengths = None
    for c, tr in zip(clips, truths):
        kp = tr.keypoints_clean
        lengths = np.stack([np.linalg.norm(kp[:, a] - kp[:, b], axis=1) for a, b in bones], axis=1)
        # Bone lengths are constant within a clip and across clips of one user.
        np.testing.assert_allclose(lengths, np.broadcast_to(lengths[0], lengths.shape), atol=1e-9)
        if first_lengths is None:
            first_lengths = lengths[0]
        np.testing.assert_allclose(lengths[0], first_lengths, atol=1e-9)
        # Joint flexion between consecutive finger bones within range.
        for ch in FINGER_CHAINS[1:]:
            seg = np.diff(kp[:, ch], axis=1)
            seg /= np.linalg.norm(seg, axis=-1, keepdims=True)
            pip = np.degrees(np.arccos(np.clip(np.sum(seg[:, 0] * seg[:, 1], -1), -1, 1)))
            dip = np.degrees(np.arccos(np.clip(np.sum(seg[:, 1] * seg[:, 2], -1), -1, 1)))
            assert pip.max() <= JOINT_LIMITS_DEG["pip"][1] + 1e-6
            assert dip.max() <= JOINT_LIMITS_DEG["dip"][1] + 1e-6
    # A hand-sized skeleton (metres): wrist to middle MCP, and the middle finger's phalanges.
    middle = bones.index((9, 10))
    assert 0.07 < first_lengths[bones.index((0, 9))] < 0.12
    assert 0.07 < first_lengths[middle : middle + 3].sum() < 0.12


def test_clips_start_from_reference_gesture(user0):
    user, clips, truths = user0
    starts = np.stack([tr.keypoints_clean[0] for tr in truths])
    # Palm down: the palm normal (index MCP - pinky MCP) x (middle MCP - wrist) points down.
    n = np.cross(starts[:, 5] - starts[:, 17], starts[:, 9] - starts[:, 0])
    assert (n[:, 2] / np.linalg.norm(n, axis=1) < -0.95).all()
    # Every clip starts with the same relaxed pose, up to tremor and slow wander.
    assert np.abs(starts - starts[0]).max() < 0.015


def test_camera_effects_present():
    _, clips, truths = simulate_user(CONFIG, 1, "in-sample", seed=2)
    lost = np.concatenate([~np.isfinite(c.keypoints).all(axis=(1, 2)) for c in clips])
    assert 0.005 < lost.mean() < 0.15
    noise = np.concatenate([(c.keypoints - tr.keypoints_clean)[np.isfinite(c.keypoints)] for c, tr in zip(clips, truths)])
    assert 0.5 * CONFIG.jitter_m < noise.std() < 2 * CONFIG.jitter_m
    quiet = replace(CONFIG, jitter_m=0.0, dropout_prob=0.0, burst_prob=0.0)
    _, clips, truths = simulate_user(quiet, 1, "in-sample", seed=2)
    np.testing.assert_allclose(clips[0].keypoints, truths[0].keypoints_clean, atol=1e-6)


def test_users_conflict():
    """The same gesture stands for different motions for different users."""
    meaning: dict = {}
    for i in range(15):
        user = make_user(CONFIG, f"u{i}", "in-sample", np.random.default_rng([0, i]))
        for (d, s), g in user.gestures.items():
            if s > 0:
                meaning.setdefault((g.kind, g.axis, g.pattern, g.sign), set()).add(d)
                meaning.setdefault((g.kind, g.axis, g.pattern, -g.sign), set()).add(-d - 1)
        # Within one user, the 12 gestures are all different.
        keys = {(g.kind, g.axis, g.pattern, g.sign) for g in user.gestures.values()}
        assert len(keys) == 12
    ambiguous = [k for k, v in meaning.items() if len(v) > 1]
    assert len(ambiguous) >= 5


def test_deterministic():
    a = generate_population(CONFIG, n_users=1, seed=4)
    b = generate_population(CONFIG, n_users=1, seed=4)
    c = generate_population(CONFIG, n_users=1, seed=5)
    np.testing.assert_array_equal(a[7].keypoints, b[7].keypoints)
    different = a[7].num_frames != c[7].num_frames or not np.array_equal(a[7].object_velocity, c[7].object_velocity)
    assert different


@pytest.mark.slow
def test_population_needs_context():
    """A context-free ridge regressor on feature windows, fitted on all training users,
    has at least twice the test MSE of the same regressor fitted per user."""
    clips = generate_population(CONFIG, n_users=15, seed=0)
    pcs = [to_policy_clip(c) for c in clips]
    r = context_need_ratio(pcs)
    print(f"context-need ratio {r['ratio']:.2f} (pooled {r['pooled_mse']:.4f}, per user {r['per_user_mse']:.4f}, "
          f"zero {r['zero_mse']:.4f})")
    assert r["per_user_mse"] < 0.6 * r["zero_mse"]  # the per-user regressor learns something real
    assert r["ratio"] >= 2.0


def test_single_stroke_users_stroke_out_and_back_and_others_are_drawn_as_before():
    """`p_single_stroke`: a user who strokes makes each move as one short stroke that comes back; the
    rest of their profile, and every user of a population without strokes, is drawn as before."""
    strokes = replace(CONFIG, p_single_stroke=1.0, single_stroke_return=(1.0, 1.0), single_stroke_s=(1.2, 1.2))
    plain, _, _ = simulate_user(CONFIG, 3, "out-sample", seed=5)
    user, clips, truths = simulate_user(strokes, 3, "out-sample", seed=5)
    assert user.single_stroke and not plain.single_stroke and user.stroke_return == 1.0
    assert user.gestures == plain.gestures and user.speed_m_s == plain.speed_m_s  # drawn before the stroke
    moves = [(c, tr) for c, tr in zip(clips, truths) if len(c.active_dims) == 1
             and user.gestures[(int(c.active_dims[0]), 1)].kind == "move"]
    assert moves
    for c, tr in moves:
        span = np.flatnonzero(tr.envelope > 0.5) / c.fps
        assert 0.7 < span[-1] - span[0] < 1.05  # the stroke's 1.2 s, less half of each ramp (0.2-0.45 s)
        palm = tr.keypoints_clean[:, [0, 5, 9, 13, 17]].mean(1)
        excursion = np.linalg.norm(palm - palm[0], axis=1)
        assert excursion.max() > 0.02 and excursion[-1] < 0.35 * excursion.max()  # out, and back
    for c, tr in zip(clips, truths):  # the label still asks for the motion over the whole stroke
        d = int(c.active_dims[0])
        assert np.abs(tr.intent[tr.envelope > 0.9, d]).min() > 0


def test_direct_users_move_and_turn_the_hand_along_each_axis_with_the_signs_they_drew():
    """`p_direct`: a direct user makes each move a move of the hand along its axis and each turn a turn of
    the wrist about it, with the signs (mirroring, flips) they drew; the rest of their profile is drawn as
    before (the choice is drawn last)."""
    for k in range(6):
        plain = make_user(CONFIG, "u", "in-sample", np.random.default_rng(k))
        direct = make_user(replace(CONFIG, p_direct=1.0), "u", "in-sample", np.random.default_rng(k))
        assert direct.speed_m_s == plain.speed_m_s and direct.mirrored == plain.mirrored
        for d in range(6):
            for s in (1, -1):
                g, p0 = direct.gestures[(d, s)], plain.gestures[(d, s)]
                assert (g.kind, g.axis) == (("move", d) if d < 3 else ("turn", d - 3))
                assert g.sign == p0.sign  # the user's own sign for the motion, whatever gesture they drew
    mixed = [make_user(replace(CONFIG, p_direct=0.0), "u", "in-sample", np.random.default_rng(k)) for k in range(20)]
    assert any(g.kind not in ("move", "turn") for u in mixed for g in u.gestures.values())


def test_tracking_glitches_shift_the_hand_on_a_few_frames_and_change_nothing_else():
    """`glitch_prob`: over a few frames the whole hand is off by a size within `glitch_m`; the labels,
    the clean hand and the other frames are as without glitches (the glitches are drawn last)."""
    quiet = replace(CONFIG, jitter_m=0.0, dropout_prob=0.0, burst_prob=0.0)
    glitchy = replace(quiet, glitch_prob=0.05, glitch_m=(0.01, 0.04), glitch_frames=(1, 3), glitch_keypoint_share=0.0)
    _, plain, plain_truths = simulate_user(quiet, 2, "in-sample", seed=3)
    _, clips, truths = simulate_user(glitchy, 2, "in-sample", seed=3)
    # The first clip is drawn from the same draws up to its glitches.
    np.testing.assert_array_equal(clips[0].object_velocity, plain[0].object_velocity)
    np.testing.assert_array_equal(truths[0].keypoints_clean, plain_truths[0].keypoints_clean)
    shifted = []
    for c, tr in zip(clips, truths):
        offset = c.keypoints.astype(np.float64) - tr.keypoints_clean
        moved = np.abs(offset).max(axis=(1, 2)) > 1e-5
        # With no keypoint share, every keypoint of a glitched frame moves by the same vector.
        np.testing.assert_allclose(offset[moved], np.repeat(offset[moved][:, :1], 21, axis=1), atol=1e-5)
        shifted.append(np.linalg.norm(offset[moved][:, 0], axis=1))
        assert moved.mean() < 0.5
    sizes = np.concatenate(shifted)
    assert sizes.size > 0
    # One glitch is 0.01-0.04 m; two that overlap add up to at most twice that.
    assert sizes.min() > 0.01 - 1e-5 and sizes.max() < 0.08 + 1e-5
    assert np.mean(sizes < 0.04 + 1e-5) > 0.8


def test_recorded_tracking_preset_is_what_generate_writes(tmp_path):
    """`generate --recorded-tracking` applies RECORDED_TRACKING and writes it in the file's generator record."""
    import json

    import h5py

    from rtcohand_drake.data.generate import main
    from rtcohand_drake.data.population.config import RECORDED_TRACKING

    out = tmp_path / "rt.h5"
    assert main(["--out", str(out), "--users", "1", "--seed", "2", "--recorded-tracking", "--quiet"]) == 0
    with h5py.File(out, "r") as f:
        generator = json.loads(f.attrs["generator"])
    for key, value in RECORDED_TRACKING.items():
        assert generator[key] == (list(value) if isinstance(value, tuple) else value)
    assert generator["glitch_prob"] > 0 and generator["jitter_m"] < CONFIG.jitter_m
    assert generator["p_repeated_rhythm"] == CONFIG.p_repeated_rhythm  # the default, unless asked
    steady = tmp_path / "steady.h5"
    assert main(["--out", str(steady), "--users", "1", "--seed", "2", "--repeated-rhythm-share", "0", "--quiet"]) == 0
    with h5py.File(steady, "r") as f:
        assert json.loads(f.attrs["generator"])["p_repeated_rhythm"] == 0.0
