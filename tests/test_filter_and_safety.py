"""MovingAverageDownsampler and SafetySupervisor, each tested alone (fixed inputs, forced updates)."""


import numpy as np
import pytest
from pydrake.systems.analysis import Simulator

from rtcohand_drake.systems.moving_average_downsampler import MovingAverageDownsampler
from rtcohand_drake.systems.safety.supervisor import Intervention, Mode, SafetySupervisor
from rtcohand_drake.scenario import Box, CommandFilter, Safety
from rtcohand_drake.interfaces import GESTURE_STATUS, OPERATOR, POLICY_MEAN, READ_VARIANCE, RESUME_COUNT, SPEED_SCALE, SAFETY_STATUS, TWIST_COMMAND, TWIST_REQUEST, WORKPIECE_POSE

R_WU = np.diag([-1.0, -1.0, 1.0])  # the inspection cell's user frame: world turned 180 deg about z
EYE = np.array([0.25, 1.0, 0.86])
BOX = Box(min_xyz=[-0.3, -0.6, 0.03], max_xyz=[0.8, 0.42, 0.9])
INSIDE = np.array([0.3, 0.0, 0.4, 1, 0, 0, 0])


def _filter_run(config, inputs, period=0.1):
    """Feeds one prediction per policy period; returns the output just before each next sample."""
    f = MovingAverageDownsampler(config, period)
    ctx = f.CreateDefaultContext()
    sim = Simulator(f, ctx)
    out = []
    for k, y in enumerate(inputs):
        f.GetInputPort(POLICY_MEAN).FixValue(ctx, np.asarray(y, float))
        f.GetInputPort(RESUME_COUNT).FixValue(ctx, [0.0])
        sim.AdvanceTo(k * period + period / 2)
        out.append(f.GetOutputPort(TWIST_REQUEST).Eval(ctx).copy())
    return np.array(out)


def test_paper_mode_is_a_2hz_mean_of_the_last_10():
    config = CommandFilter(mode="paper", window=10, command_period_s=0.5, clamp=[1.0] * 6)
    ys = [[0.01 * k, 0, 0, 0, 0, 0] for k in range(30)]
    out = _filter_run(config, ys)
    # Held constant between 2 Hz updates.
    changes = np.flatnonzero(np.any(np.diff(out, axis=0) != 0, axis=1)) + 1
    assert set(changes) <= {5, 10, 15, 20, 25}
    # At t = 2.0 s (sample 20), the command is the mean of predictions 11..20.
    assert out[20, 0] == pytest.approx(np.mean([0.01 * k for k in range(11, 21)]))


def test_paper_mode_clamps_per_axis():
    config = CommandFilter(mode="paper", clamp=[0.05, 0.05, 0.05, 0.2, 0.2, 0.2])
    out = _filter_run(config, [[1.0, -1.0, 0.01, 5.0, 0, -5.0]] * 12)
    assert np.allclose(out[-1], [0.05, -0.05, 0.01, 0.2, 0, -0.2])


def test_responsive_mode_follows_faster_and_is_rate_limited():
    step = [[0.1, 0, 0, 0, 0, 0]] * 20
    paper = _filter_run(CommandFilter(mode="paper"), step)
    resp_cfg = CommandFilter(mode="responsive", responsive_window=3, max_linear_accel_m_s2=0.5)
    responsive = _filter_run(resp_cfg, step)
    # Onset: first sample above 20% of the final value.
    onset = lambda out: int(np.argmax(out[:, 0] > 0.02))
    assert onset(responsive) * 3 <= onset(paper)
    assert np.all(np.abs(np.diff(responsive[:, 0])) <= 0.5 * 0.1 + 1e-12)


def test_non_finite_predictions_count_as_zero():
    out = _filter_run(CommandFilter(mode="responsive"), [[np.nan, np.inf, 0, 0, 0, 0]] * 5)
    assert np.all(np.isfinite(out)) and np.allclose(out, 0)


def test_deadband_zeroes_small_axes_passes_large_ones_and_is_continuous():
    from rtcohand_drake.systems.moving_average_downsampler import apply_deadband

    d = np.array([0.01, 0.01, 0.01, 0.1, 0.1, 0.1])
    x = np.array([0.008, -0.015, 0.05, -0.1, 0.15, 0.5])
    # 0 within d; x (|x| - d) / d between d and 2 d; x beyond 2 d.
    assert np.allclose(apply_deadband(x, d), [0.0, -0.0075, 0.05, 0.0, 0.075, 0.5])
    grid = np.linspace(-0.5, 0.5, 20001)
    y = apply_deadband(np.repeat(grid[:, None], 6, axis=1), d)
    assert np.max(np.abs(np.diff(y[:, 3]))) < 3 * (grid[1] - grid[0])  # no jump at d or 2 d
    assert np.array_equal(apply_deadband(x, np.zeros(6)), x)
    # In the filter (both modes): a rest drift commands nothing, a gesture's twist passes.
    for mode in ("paper", "responsive"):
        drift = _filter_run(CommandFilter(mode=mode, deadband=list(d)), [[0.005, 0, 0, 0.04, -0.05, 0.03]] * 12)
        assert np.allclose(drift, 0.0)
        stroke = _filter_run(CommandFilter(mode=mode, deadband=list(d)), [[0.1, 0, 0, 0, 0, 0.5]] * 12)
        assert np.allclose(stroke[-1], [0.1, 0, 0, 0, 0, 0.5])


def test_a_deadband_of_half_the_clamp_or_more_is_refused(tmp_path):
    from rtcohand_drake.scenario import ScenarioError, load_scenario, resolve_scenario_path

    import re

    text = re.sub(r"\n  deadband: \[[^\]]*\]", "\n  deadband: [0.1, 0, 0, 0, 0, 0]",
                  resolve_scenario_path("inspection").read_text())
    assert "deadband: [0.1, 0, 0, 0, 0, 0]" in text
    path = tmp_path / "bad.yaml"
    path.write_text(text)
    with pytest.raises(ScenarioError, match="deadband"):
        load_scenario(path)


def _supervisor(config=None, command_period=0.5, box=BOX):
    config = config or Safety()
    s = SafetySupervisor(config, box, R_WU, EYE, command_period)
    ctx = s.CreateDefaultContext()
    return s, ctx, Simulator(s, ctx)


def _fix(s, ctx, request, valid=1.0, frame_time=None, pose=INSIDE, pause=0.0, sensitivity=1.0):
    s.GetInputPort(TWIST_REQUEST).FixValue(ctx, np.asarray(request, float))
    t = ctx.get_time() if frame_time is None else frame_time
    s.GetInputPort(GESTURE_STATUS).FixValue(ctx, [valid, t])
    s.GetInputPort(WORKPIECE_POSE).FixValue(ctx, np.asarray(pose, float))
    s.GetInputPort(OPERATOR).FixValue(ctx, [pause, sensitivity])


def _advance(s, ctx, sim, seconds, **inputs):
    """Advances in supervisor periods, refreshing the gesture timestamp unless told otherwise."""
    out = []
    end = ctx.get_time() + seconds
    while ctx.get_time() < end - 1e-9:
        _fix(s, ctx, **inputs)
        sim.AdvanceTo(ctx.get_time() + 0.02)
        out.append((s.GetOutputPort(TWIST_COMMAND).Eval(ctx).copy(), s.GetOutputPort(SAFETY_STATUS).Eval(ctx).copy()))
    return out


def test_passes_a_valid_request_and_applies_sensitivity():
    s, ctx, sim = _supervisor()
    out = _advance(s, ctx, sim, 1.0, request=[0.05, 0, 0, 0, 0, 0.2], sensitivity=2.0)
    assert np.allclose(out[-1][0], [0.1, 0, 0, 0, 0, 0.4])
    assert out[-1][1][0] == Mode.RUNNING


@pytest.mark.parametrize("variance, scale", [(1.02, 1.0), (1.1, 1.0), (1.35, 0.65), (1.6, 0.3), (9.0, 0.3),
                                             (np.inf, 0.3), (np.nan, 0.3)])
def test_confidence_scales_the_request_by_the_read_variance(variance, scale):
    """Full speed for a gesture like the context (v <= 1.1), down to the 0.3 floor at v >= 1.6."""
    s, ctx, sim = _supervisor()
    s.GetInputPort(READ_VARIANCE).FixValue(ctx, [variance])
    out = _advance(s, ctx, sim, 1.0, request=[0.05, 0, 0, 0, 0, 0.2])
    assert np.allclose(out[-1][0], scale * np.array([0.05, 0, 0, 0, 0, 0.2]))
    assert s.GetOutputPort(SPEED_SCALE).Eval(ctx)[0] == pytest.approx(scale)
    assert bool(int(out[-1][1][2]) & Intervention.LOW_CONFIDENCE) == (scale < 1.0)


def test_confidence_scaling_off_and_unconnected_leave_the_request_alone():
    s, ctx, sim = _supervisor(Safety(confidence_scaling=False))
    s.GetInputPort(READ_VARIANCE).FixValue(ctx, [5.0])
    assert np.allclose(_advance(s, ctx, sim, 1.0, request=[0.05, 0, 0, 0, 0, 0])[-1][0][0], 0.05)
    s, ctx, sim = _supervisor()
    assert np.allclose(_advance(s, ctx, sim, 1.0, request=[0.05, 0, 0, 0, 0, 0])[-1][0][0], 0.05)
    assert s.GetOutputPort(SPEED_SCALE).Eval(ctx)[0] == 1.0


def test_sensitivity_is_clipped_to_its_range():
    s, ctx, sim = _supervisor()
    out = _advance(s, ctx, sim, 1.0, request=[0.04, 0, 0, 0, 0, 0], sensitivity=10.0)
    assert out[-1][0][0] == pytest.approx(0.08)  # 2x at most


def test_speed_limits_clamp_and_report():
    s, ctx, sim = _supervisor()
    out = _advance(s, ctx, sim, 2.0, request=[1.0, 1.0, 0, 3.0, 0, 0])
    cmd, status = out[-1]
    assert np.linalg.norm(cmd[:3]) == pytest.approx(0.25)
    assert np.linalg.norm(cmd[3:]) == pytest.approx(1.0)
    assert int(status[2]) & Intervention.SPEED_CLAMP


@pytest.mark.parametrize("command_period", [0.5, 0.1])
@pytest.mark.parametrize("fault", ["invalid", "stale", "nan"])
def test_watchdog_zeroes_the_command_within_one_command_period(fault, command_period):
    s, ctx, sim = _supervisor(command_period=command_period)
    _advance(s, ctx, sim, 1.0, request=[0.1, 0, 0, 0, 0, 0.5])
    t_fault = ctx.get_time()
    kwargs = {"request": [0.1, 0, 0, 0, 0, 0.5]}
    if fault == "invalid":
        kwargs["valid"] = 0.0
    elif fault == "stale":
        kwargs["frame_time"] = t_fault - 0.0  # the last frame; time moves on without a new one
    else:
        kwargs["request"] = [np.nan, 0, 0, 0, 0, 0.5]
    stale_after = Safety().stale_after_s if fault == "stale" else 0.0
    out = _advance(s, ctx, sim, stale_after + command_period + 0.1, **kwargs)
    deadline = int(round((stale_after + command_period) / 0.02))
    assert np.allclose(out[deadline - 1][0], 0.0, atol=1e-12), out[deadline - 1]
    assert out[-1][1][0] == Mode.WATCHDOG
    norms = [np.linalg.norm(c) for c, _ in out]
    assert all(b <= a + 1e-12 for a, b in zip(norms, norms[1:]))  # decays, never grows


def test_pause_brings_to_rest_smoothly_and_resume_counts():
    cfg = Safety(pause_ramp_s=0.5)
    s, ctx, sim = _supervisor(cfg)
    _advance(s, ctx, sim, 1.0, request=[0.1, 0, 0, 0, 0, 0])
    paused = _advance(s, ctx, sim, 1.0, request=[0.1, 0, 0, 0, 0, 0], pause=1.0)
    speeds = [c[0] for c, _ in paused]
    assert speeds[0] > 0 and np.allclose(speeds[25:], 0.0)  # at rest within the 0.5 s ramp
    assert max(abs(np.diff(speeds))) <= 0.1 * 0.02 / 0.5 + 1e-12  # a linear ramp, no jump
    assert paused[-1][1][0] == Mode.PAUSED and paused[-1][1][1] == 0
    resumed = _advance(s, ctx, sim, 0.5, request=[0.1, 0, 0, 0, 0, 0])
    assert resumed[-1][1][1] == 1 and resumed[-1][1][0] == Mode.RUNNING


def test_workspace_box_stops_outward_motion_only():
    near_top = np.array([0.3, 0.0, 0.895, 1, 0, 0, 0])
    s, ctx, sim = _supervisor()
    out = _advance(s, ctx, sim, 1.0, request=[0.05, 0, 0.1, 0, 0, 0], pose=near_top)
    cmd, status = out[-1]
    assert cmd[2] == pytest.approx(0.0, abs=1e-12)  # no further up
    assert cmd[0] == pytest.approx(0.05)  # sideways motion kept
    assert int(status[2]) & Intervention.WORKSPACE
    down = _advance(s, ctx, sim, 1.0, request=[0, 0, -0.1, 0, 0, 0], pose=near_top)
    assert down[-1][0][2] == pytest.approx(-0.1)  # back inside is allowed


def test_inspector_zone_blocks_approach_to_the_eye():
    # Just outside the zone, in front of the eye (U +y is world -y).
    close = np.concatenate([EYE + [0, -0.555, 0], [1, 0, 0, 0]])
    wide = Box(min_xyz=[-2, -2, -2], max_xyz=[2, 2, 2])  # only the inspector zone can act
    s, ctx, sim = _supervisor(Safety(min_inspector_distance_m=0.55), box=wide)
    out = _advance(s, ctx, sim, 1.0, request=[0, -0.1, 0, 0, 0, 0], pose=close)  # U -y: toward the inspector
    cmd, status = out[-1]
    assert cmd[1] == pytest.approx(0.0, abs=1e-12)
    assert int(status[2]) & Intervention.INSPECTOR_ZONE
    away = _advance(s, ctx, sim, 1.0, request=[0, 0.1, 0, 0, 0, 0], pose=close)
    assert away[-1][0][1] == pytest.approx(0.1)


def test_mold_exit_corridor_passes_only_motion_along_the_mold_axis():
    from pydrake.math import RigidTransform

    mold = RigidTransform([0.45, -0.12, 0.03])  # the inspection cell's mold frame: cavity floor centre, z up
    s = SafetySupervisor(Safety(), BOX, R_WU, EYE, 0.5, X_W_mold=mold)
    ctx = s.CreateDefaultContext()
    sim = Simulator(s, ctx)
    in_cavity = np.array([0.45, -0.12, 0.03 + 0.052, 1, 0, 0, 0])  # the part at rest in the mold
    ask = [0.1, -0.05, 0.08, 0.3, -0.2, 0.5]  # sideways, up and turning at once
    cmd, status = _advance(s, ctx, sim, 1.0, request=ask, pose=in_cavity)[-1]
    assert np.allclose(cmd, [0, 0, 0.08, 0, 0, 0], atol=1e-12)  # U z is world z: only the lift passes
    assert int(status[2]) & Intervention.MOLD_EXIT
    # Seated in the cavity, the part may not be pushed further down; a little higher it may.
    down = [0.0, 0.0, -0.05, 0.2, 0.0, 0.0]
    cmd, _ = _advance(s, ctx, sim, 1.0, request=down, pose=in_cavity)[-1]
    assert np.allclose(cmd, 0.0, atol=1e-12)
    raised = np.r_[0.45, -0.12, 0.03 + 0.07, 1, 0, 0, 0]
    cmd, _ = _advance(s, ctx, sim, 1.0, request=down, pose=raised)[-1]
    assert np.allclose(cmd, [0, 0, -0.05, 0, 0, 0], atol=1e-12)
    # Above the exit height (0.10 m over the floor) but below the turn height (0.145 m) the part
    # may move any way but not turn: a turn would swing a corner into the walls.
    above_walls = np.r_[0.45, -0.12, 0.03 + 0.11, 1, 0, 0, 0]
    cmd, status = _advance(s, ctx, sim, 2.0, request=ask, pose=above_walls)[-1]
    assert np.allclose(cmd, ask[:3] + [0, 0, 0], atol=1e-9)
    assert int(status[2]) & Intervention.MOLD_EXIT
    # Above the turn height or beside the cavity, everything passes again.
    for clear in ([0.45, -0.12, 0.03 + 0.15], [0.45 + 0.083 + 0.03, -0.12, 0.03 + 0.052]):
        cmd, status = _advance(s, ctx, sim, 2.0, request=ask, pose=np.r_[clear, 1, 0, 0, 0])[-1]
        assert np.allclose(cmd, ask, atol=1e-9), clear
        assert not int(status[2]) & Intervention.MOLD_EXIT
    # Switched off by a height of 0.
    off = SafetySupervisor(Safety(mold_exit_height_m=0.0), BOX, R_WU, EYE, 0.5, X_W_mold=mold)
    octx = off.CreateDefaultContext()
    cmd, _ = _advance(off, octx, Simulator(off, octx), 2.0, request=ask, pose=in_cavity)[-1]
    assert np.allclose(cmd, ask, atol=1e-9)


def _finger_along_the_palm_across_axis(tilt_m: float, aside_m: float = 0.0) -> np.ndarray:
    """21 keypoints (U): a flat hand whose index finger points along the palm frame's x axis (its
    across axis), its tip `tilt_m` above or below the palm's plane and `aside_m` toward the fingers:
    the finger frame's reference axis lines up with the finger itself."""
    from rtcohand_drake.data.hand_features import part_frames

    kp = np.zeros((21, 3))
    for k, x in zip((5, 9, 13, 17), (0.03, 0.01, -0.01, -0.03)):  # MCPs across the palm, 8 cm ahead of the wrist
        kp[k] = [x, 0.08, 0.0]
        kp[k + 1:k + 4] = kp[k] + np.outer([1, 2, 3], [0.0, 0.025, 0.0])  # fingers straight ahead
    kp[1:5] = [0.03, 0.02, 0.0] + np.outer([1, 2, 3, 4], [0.012, 0.01, 0.0])
    palm = part_frames(kp)[0][0]  # columns e_x (across), e_y, e_z (the palm's normal)
    kp[6:9] = kp[5] + np.outer([1, 2, 3], 0.025 * palm[:, 0] + aside_m / 3 * palm[:, 1] + tilt_m / 3 * palm[:, 2])
    return kp


def test_a_finger_frame_turning_half_a_turn_is_not_an_implausible_hand():
    """Two poses 0.1 s apart whose index finger tips by 2 mm across its line with the palm's across axis
    (and 0.2 mm aside): the finger's frame turns nearly half a turn, 29 rad/s (pi / 0.1 s is 31), while
    the hand barely moves, as 1-1.5 % of the policy steps of real footage and recorded people do.
    Not a fault; a linear velocity over 25 m/s, or a turn over 100 rad/s, is."""
    from rtcohand_drake.data.hand_features import part_frames, part_velocities
    from rtcohand_drake.interfaces import GESTURE_FEATURES
    from rtcohand_drake.systems.safety.rules import plausible_features

    (R0, o0), (R1, o1) = part_frames(_finger_along_the_palm_across_axis(0.001)), \
        part_frames(_finger_along_the_palm_across_axis(-0.001, 0.0002))
    x = part_velocities(R0, o0, R1, o1, 0.1)
    turn = np.linalg.norm(x.reshape(6, 6)[:, 3:], axis=1)
    assert turn[2] > 25.0 and np.abs(x.reshape(6, 6)[:, :3]).max() < 0.1  # the index finger's frame, nothing else
    assert np.all(np.delete(turn, 2) < 1e-9)
    assert plausible_features(x, Safety())
    fast, spun = np.zeros(36), np.zeros(36)
    fast[6] = 26.0  # the thumb's origin at 26 m/s
    spun[3] = 150.0  # the palm turning at 150 rad/s
    assert not plausible_features(fast, Safety()) and not plausible_features(spun, Safety())
    assert not plausible_features(x, Safety(max_plausible_angular_feature=25.0))
    for features, mode in ((x, Mode.RUNNING), (fast, Mode.WATCHDOG), (spun, Mode.WATCHDOG)):
        s, ctx, sim = _supervisor(command_period=0.1)
        s.GetInputPort(GESTURE_FEATURES).FixValue(ctx, features)
        out = _advance(s, ctx, sim, 0.5, request=[0.05, 0, 0, 0, 0, 0.2])
        assert out[-1][1][0] == mode
        assert np.allclose(out[-1][0], [0.05, 0, 0, 0, 0, 0.2] if mode == Mode.RUNNING else 0.0, atol=1e-12)
