"""The rest release and the jump guard (learning.rest_release), and the command hold
(learning.command_hold), alone and in the policy box.

The people here are written by the tests: a hand that strokes along one axis per command and rests,
still, before and after each stroke, as the recorded people of `data.import_shrec17` do.
"""

import numpy as np
import pytest

from rtcohand_drake.cell.robot_files import models_dir
from rtcohand_drake.data.hand_features import (FEATURE_DIM, PathShapeStream, hand_features, join_recordings,
                                               path_shape_features)
from rtcohand_drake.interfaces import GESTURE_FEATURES, KEYPOINTS, POLICY_MEAN
from rtcohand_drake.learning import rest_release as rr
from rtcohand_drake.systems.policy import CchpPolicy

RATE = 10.0
FULL = np.array([0.12, 0.12, 0.12, 0.6, 0.6, 0.6])


def _hand() -> np.ndarray:
    """(21, 3) a right hand, palm down, fingers forward (U)."""
    points = [[0.0, 0.0, 0.0]]
    for f, x in enumerate((-0.04, -0.02, 0.0, 0.02, 0.04)):
        for j in range(4):
            points.append([x * (1.0 + 0.2 * j) - (0.03 if f == 0 else 0.0), 0.06 + 0.025 * j, -0.005 * j])
    return np.asarray(points) + np.array([0.1, 0.3, 0.0])


def _stroke_clip(command: int, rng, rest: int = 6, moving: int = 14, still_label: bool = False):
    """(keypoints (T, 21, 3) at RATE, labels (T, 6)): still, a stroke of the hand along the command's
    direction with its label, still again. `still_label`: the label goes on over the still hand after
    the stroke (a person who commands with a held hand)."""
    dim, sign = command // 2, 1 - 2 * (command % 2)
    direction = np.zeros(3)
    direction[dim % 3] = sign
    if dim >= 3:  # a turn: move along the turn's axis crossed with Y, enough to tell them apart
        direction = np.cross(direction, [0.0, 1.0, 0.0]) + 0.3 * direction
    speed = 0.25 * (1.0 + 0.1 * rng.standard_normal())
    path = np.concatenate([np.zeros(rest), np.cumsum(np.full(moving, speed / RATE)), np.full(rest, speed * moving / RATE)])
    keypoints = _hand()[None] + path[:, None, None] * direction + 0.0001 * rng.standard_normal((len(path), 21, 3))
    labels = np.zeros((len(path), 6))
    labels[rest:rest + moving, dim] = sign * FULL[dim]
    if still_label:
        labels[rest + moving:, dim] = sign * FULL[dim]
    return keypoints, labels


def _pieces(rng, still_label=False, path_shape=False):
    pieces = []
    for rep in range(3):
        for command in range(12):
            kp, y = _stroke_clip(command, rng, still_label=still_label)
            x, _ = hand_features(kp, RATE, RATE)
            if path_shape:
                x = np.hstack([x, path_shape_features(kp, RATE, RATE)])
            pieces.append((x.astype(np.float32), y.astype(np.float32)))
    return pieces


def test_gate_falls_as_written_and_only_for_a_person_who_rests():
    rng = np.random.default_rng(0)
    resting = rr.fit_rest_release(_pieces(rng))
    assert resting.on and resting.harm <= rr.HARM and 0.0 < resting.theta
    # The gate as the module docstring writes it: 1 up to STILL_FROM still steps, 0 from STILL_TO.
    for n in range(6):
        expected = 1.0 if n <= rr.STILL_FROM else 0.0 if n >= rr.STILL_TO else (rr.STILL_TO - n) / (rr.STILL_TO - rr.STILL_FROM)
        assert resting.gate(n) == pytest.approx(expected)
    # The still count: motion under theta counts up, motion over it starts again at 0.
    x_still = np.zeros(FEATURE_DIM)
    x_moving = rr.SCALES * 2.0 * resting.theta
    assert resting.next_count(2.0, x_still) == 3.0 and resting.next_count(2.0, x_moving) == 0.0
    # theta against its definition, written out: 1.5 x the 95th percentile of the rest steps' motion
    # (none within 2 steps of a label), or f x the median motion of the commanding steps.
    pieces = _pieces(np.random.default_rng(0))
    x = np.concatenate([p[0] for p in pieces]).astype(np.float64)
    y = np.concatenate([p[1] for p in pieces]).astype(np.float64)
    scales = np.tile([0.1, 0.1, 0.1, 1.0, 1.0, 1.0], 6)  # 0.1 m/s counts as 1 rad/s
    m = np.sqrt(np.mean((x / scales) ** 2, axis=1))
    labelled = np.abs(y).max(1) > 0
    near = labelled.copy()
    for s in (1, 2):
        near[s:] |= labelled[:-s]
        near[:-s] |= labelled[s:]
    # (steps near a label in the next piece are counted per piece in the module; here the pieces
    # are long enough at rest that the difference is none)
    # f: the largest of 0.5, 0.4, 0.3, 0.2, 0.1 with which the release takes at most 5 % of the labels'
    # squared size over the person's own clips (the gate over each clip from a still count of 0).
    jitter, commanding = 1.5 * np.quantile(m[~near], 0.95), np.median(m[(np.abs(y) / FULL).max(1) >= 0.2])

    def harm(theta):
        taken = 0.0
        for f, l in pieces:
            still = np.sqrt(np.mean((f.astype(np.float64) / scales) ** 2, axis=1)) < theta
            n, gate = 0, []
            for s_t in still:
                n = n + 1 if s_t else 0
                gate.append(1.0 if n <= 1 else 0.0 if n >= 3 else (3 - n) / 2)
            taken += float((((1.0 - np.array(gate)) ** 2)[:, None] * l.astype(np.float64) ** 2).sum())
        return taken / (y ** 2).sum()

    floor = next(f for f in (0.5, 0.4, 0.3, 0.2, 0.1) if harm(max(jitter, f * commanding)) <= 0.05)
    assert resting.floor == floor and resting.theta == pytest.approx(max(jitter, floor * commanding), rel=1e-6)
    assert resting.harm == pytest.approx(harm(resting.theta), rel=1e-6)
    if floor < 0.5:  # the next larger floor would take too much
        assert harm(max(jitter, (floor + 0.1) * commanding)) > 0.05
    # A person whose labels go on over a still hand keeps the policy's output as it is.
    holding = rr.fit_rest_release(_pieces(np.random.default_rng(1), still_label=True))
    assert not holding.on and holding.harm > rr.HARM and holding.gate(10) == 1.0
    # What the run and the reading check say of each: nothing when on; why, when off.
    assert rr.release_advice(resting) is None
    advice = rr.release_advice(holding)
    assert "off" in advice and f"{100 * holding.harm:.0f} %" in advice and "\n" not in advice
    assert "no rest between gestures" in rr.release_advice(rr.RestRelease())


def test_the_gates_over_a_stream_are_the_box_s_step_by_step_gates():
    """`gates` (one pass over an array, as the fit and the benchmarks use it) gives exactly what the box's
    `next_count` and `gate` give step by step, from a still count of 0: lost (NaN) steps, runs of still
    steps longer and shorter than the gate's fall, a release that is off."""
    rng = np.random.default_rng(3)
    for trial in range(40):
        n = int(rng.integers(1, 60))
        x = rr.SCALES * rng.uniform(0.0, 2.0, (n, 1)) * rng.uniform(0.5, 1.5, (n, FEATURE_DIM))
        x[rng.random(n) < 0.4] *= 0.01  # still steps, in runs of every length
        x[rng.random((n, FEATURE_DIM)) < 0.02] = np.nan
        release = rr.RestRelease(theta=0.5, on=trial % 5 != 0)
        count, expected = 0.0, []
        for step in x:
            count = release.next_count(count, step)
            expected.append(release.gate(count))
        assert np.array_equal(release.gates(x), np.array(expected))
        assert np.array_equal(rr.motions(x), np.array([release.motion(step) for step in x]))
    assert rr.RestRelease(theta=0.5, on=True).gates(np.zeros((0, FEATURE_DIM))).shape == (0,)


def test_labels_placed_later_than_the_gesture_are_fitted_where_the_gesture_is(tmp_path):
    """A recorder session's labels follow the gesture by the protocol's `label_lag_s`: fitted as they are,
    each outlasts the still hand and the release turns itself off; fitted with the lag, it is the release
    of the same person with labels on the gesture, exactly. The lag comes from the recorder's file."""
    import json

    import h5py

    from rtcohand_drake.data.dataset import label_lag_s

    on_time = _pieces(np.random.default_rng(0))
    lag = 4  # 0.4 s at RATE: the recorder's label_lag_s
    late = [(x, np.vstack([np.zeros((lag, 6), np.float32), y[:-lag]])) for x, y in on_time]
    assert not rr.fit_rest_release(late).on
    fitted, reference = rr.fit_rest_release(late, lag), rr.fit_rest_release(on_time)
    assert fitted.on and (fitted.theta, fitted.harm, fitted.floor) == (reference.theta, reference.harm, reference.floor)
    # The policy box fits its release for the lag it is given (the run passes the context files' lag).
    assert not CchpPolicy(models_dir() / "cchp_default.pt", late, RATE).release.on
    box = CchpPolicy(models_dir() / "cchp_default.pt", late, RATE, label_lag_s=0.4)
    assert box.release.on and box.release.theta == reference.theta
    # label_lag_s: the recorder's protocol for cue labels; 0 for any other file.
    path = tmp_path / "session.h5"
    with h5py.File(path, "w") as f:
        f.attrs["label_source"] = "cue"
        f.attrs["recorder"] = json.dumps({"source": "camera 0", "protocol": {"label_lag_s": 0.4}})
    assert label_lag_s(path) == 0.4 and label_lag_s([path, path]) == 0.4
    with h5py.File(path, "r+") as f:
        f.attrs["label_source"] = "aruco"
    assert label_lag_s(path) == 0.0


def _box(model, pieces, rest_release=True, command_hold=True):
    """The box with a file of models/ (a name) or any path."""
    policy = CchpPolicy(models_dir() / model, pieces, RATE, seed=0, rest_release=rest_release,
                        command_hold=command_hold)
    return policy, policy.CreateDefaultContext()


def _step(policy, context, x, keypoints=None):
    policy.GetInputPort(GESTURE_FEATURES).FixValue(context, np.asarray(x, float)[:FEATURE_DIM])
    if keypoints is not None:
        policy.GetInputPort(KEYPOINTS).FixValue(context, np.asarray(keypoints, float).reshape(-1))
    context.SetDiscreteState(policy.EvalUniquePeriodicDiscreteUpdate(context))
    return policy.GetOutputPort(POLICY_MEAN).Eval(context).copy()


def test_the_command_lets_go_within_half_a_second_once_the_hand_rests():
    """The shipped file in the box, a person who rests between strokes: from the third still period
    on (0.3 s) the command is nothing, below a fifth of a full command within 0.5 s; before, and
    without the release, it is the policy's own output."""
    pieces = _pieces(np.random.default_rng(2))
    released, c1 = _box("cchp_default.pt", pieces)
    kept, c2 = _box("cchp_default.pt", pieces, rest_release=False)
    assert released.release.on and not kept.release.on
    kp, _ = _stroke_clip(6, np.random.default_rng(3), rest=0, moving=14)
    x, _ = hand_features(kp, RATE, RATE)
    stream = np.vstack([x[1:], np.zeros((10, FEATURE_DIM))])  # the stroke, then the hand at rest
    outs = np.array([[_step(p, c, xi) for p, c in ((released, c1), (kept, c2))] for xi in stream])
    moving = len(x) - 1
    np.testing.assert_allclose(outs[:moving, 0], outs[:moving, 1], atol=1e-7)  # the stroke: untouched
    assert np.abs(outs[:moving, 0]).max() > 0.0
    gates = [released.release.gate(n) for n in range(1, 11)]
    np.testing.assert_allclose(outs[moving:, 0], outs[moving:, 1] * np.array(gates)[:, None], atol=1e-7)
    rested = outs[moving + rr.STILL_TO - 1:, 0]  # still for STILL_TO periods: 0.3 s
    assert np.all(np.abs(rested) / FULL <= 0.2) and np.all(rested == 0.0)


def test_a_jump_of_the_hand_between_two_gestures_commands_no_motion():
    """The file for real hands in the box: the hand jumps 0.4 m in one period between two strokes.
    The box steps exactly as if the hand had not moved in that period and its path started there."""
    rng = np.random.default_rng(4)
    pieces = _pieces(rng, path_shape=True)
    guarded, c1 = _box("cchp_path_shape.pt", pieces)
    assert np.isfinite(guarded.release.jump)
    first, _ = _stroke_clip(0, rng)
    second, _ = _stroke_clip(4, rng)
    second = second + np.array([0.0, 0.0, 0.4])  # the hand re-found 0.4 m higher
    keypoints = np.concatenate([first, second])
    x, _ = hand_features(keypoints, RATE, RATE)
    at = len(first)  # the period the hand jumps in
    assert guarded.release.is_jump(x[at]) and not any(guarded.release.is_jump(v) for v in np.delete(x, at, 0))
    outs = np.array([_step(guarded, c1, xi, k) for xi, k in zip(x, keypoints)])
    # The same box fed no motion in that period, its path started afresh there.
    reference, c2 = _box("cchp_path_shape.pt", pieces)
    expected = []
    for t, (xi, k) in enumerate(zip(x, keypoints)):
        if t == at:
            xi = np.zeros(FEATURE_DIM)
            stream = PathShapeStream(RATE)
            state = c2.get_mutable_discrete_state(reference._shape)
            state.SetFromVector(stream.state)
        expected.append(_step(reference, c2, xi, k))
    np.testing.assert_allclose(outs, np.array(expected), atol=1e-6)
    # The offline guard reads the same stream the same way.
    guarded_x = rr.guard_stream(guarded.release, x, keypoints, RATE)
    assert np.all(guarded_x[at, :FEATURE_DIM] == 0.0) and np.all(guarded_x[at + 1, :FEATURE_DIM] == x[at + 1])
    fresh = PathShapeStream(RATE)
    assert np.allclose(guarded_x[at, FEATURE_DIM:], fresh.update(keypoints[at])[0])


def test_recordings_join_without_a_jump():
    rng = np.random.default_rng(5)
    a, _ = _stroke_clip(0, rng)
    b, _ = _stroke_clip(2, rng)
    b = b + np.array([0.3, -0.2, 0.1])
    b[:2] = np.nan  # the hand is not seen in the second recording's first frames
    joined = join_recordings([a, b])
    np.testing.assert_array_equal(joined[0], a)
    np.testing.assert_allclose(joined[1][2].mean(0), a[-1].mean(0), atol=1e-12)
    np.testing.assert_allclose(joined[1][2:] - joined[1][2], b[2:] - b[2], atol=1e-12)  # moved, not changed
    assert np.isnan(joined[1][:2]).all()


def test_the_command_hold_as_written():
    """A command the output points along at >= high of its size for steps_on steps is held (share of it
    at full size, the rest the output) until the output along it is under low for steps_off steps (it
    fades, or turns to another command); another command that does the same takes over; an axis the
    person never commands is never held."""
    from rtcohand_drake.learning.command_hold import CommandHold

    sizes = np.array([0.12, 0.12, 0.0, 0.6, 0.6, 0.6])  # no Tz in this person's context
    hold = CommandHold(sizes, high=0.3, steps_on=3, low=0.1, steps_off=2, share=0.5)
    y = np.zeros((15, 6))
    y[0:4, 0] = 0.05  # +Tx at 0.42 of its size: held from the third step (index 2)
    y[4, 0] = 0.02  # 0.17: not low, the hold stays
    y[5:7, 0] = 0.005  # 0.04, twice: the hold ends at the second (index 6)
    y[7:12, 4] = -0.3  # -Ry at 0.5: held from index 9
    y[10:12, 2] = 0.5  # a large Tz, which this person never commands: not read as a command, and Ry stays held
    y[12:, 3] = 0.12  # the read turns to +Rx at 0.2 (not yet a command to hold): -Ry is let go at index 13
    out = hold.apply(y)
    expected = y.copy()
    for steps, axis, command in (((2, 3, 4, 5), 0, 0.12), ((9, 10, 11, 12), 4, -0.6)):
        for t in steps:  # half the held command at its full size, half the output (all of it)
            expected[t] = 0.5 * y[t]
            expected[t, axis] += 0.5 * command
    np.testing.assert_allclose(out, expected, atol=1e-12)
    with pytest.raises(ValueError, match="low < high"):
        CommandHold(sizes, high=0.1, low=0.2)


def test_the_box_holds_what_the_file_asks_for_and_lets_go_at_rest(tmp_path):
    """The file for real hands built asking for the hold (`path_shape_policy --hold`): in the box a
    stroke's command is held as `CommandHold.apply` holds the unheld box's output, and once the hand
    rests the command is nothing from the fourth still period on (0.4 s). With `policy.command_hold:
    false`, or a file that asks for none (the shipped files), the box holds nothing."""
    from rtcohand_drake.learning import path_shape_policy as psp
    from rtcohand_drake.learning.command_hold import hold_settings
    from rtcohand_drake.learning.policy_file import load_policy
    from rtcohand_drake.scenario import load_scenario

    rng = np.random.default_rng(6)
    pieces = _pieces(rng, path_shape=True)
    asking = psp.build_path_shape_policy(models_dir() / "cchp_default.pt", tmp_path / "held.pt", hold=psp.HOLD_CHOSEN)
    assert hold_settings(load_policy(asking)) == list(psp.HOLD_CHOSEN)
    held, c1 = _box(asking, pieces)
    plain, c2 = _box(asking, pieces, command_hold=False)
    assert _box("cchp_path_shape.pt", pieces)[0].hold is None
    assert held.hold is not None and plain.hold is None
    np.testing.assert_allclose(held.hold.sizes, FULL, rtol=1e-6)  # the person's command sizes
    assert load_scenario("inspection").policy.command_hold is True
    assert hold_settings(load_policy(models_dir() / "cchp_default.pt")) is None
    assert _box("cchp_default.pt", _pieces(rng))[0].hold is None
    kp, _ = _stroke_clip(0, rng, rest=0, moving=14)  # +Tx
    x, _ = hand_features(kp, RATE, RATE)
    still = np.repeat(kp[-1:], 10, axis=0)
    stream = [(xi, k) for xi, k in zip(x[1:], kp[1:])] + [(np.zeros(FEATURE_DIM), k) for k in still]
    outs = np.array([[_step(p, c, xi, k) for p, c in ((held, c1), (plain, c2))] for xi, k in stream])
    np.testing.assert_allclose(outs[:, 0], held.hold.apply(outs[:, 1]), atol=1e-6)
    moving = len(x) - 1
    assert np.any(np.abs(outs[:moving, 0] - outs[:moving, 1]) > 1e-3)  # the hold took hold in the stroke
    assert outs[:moving, 0, 0].mean() > outs[:moving, 1, 0].mean()  # and moved the part further along +Tx
    assert np.all(outs[moving + 3:, 0] == 0.0)  # still from the first rest period: nothing from the fourth
