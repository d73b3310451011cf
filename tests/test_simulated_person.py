"""The simulated operator: anatomical hands, that user's own gestures, a task that progresses, determinism."""

from dataclasses import replace

import numpy as np
import pytest
from pydrake.systems.analysis import Simulator
from pydrake.systems.framework import DiagramBuilder
from pydrake.systems.primitives import ConstantVectorSource, LogVectorOutput

from rtcohand_drake.data.dataset import to_policy_clip
from rtcohand_drake.data.population import GeneratorConfig, simulate_user, user_groups
from rtcohand_drake.errors import InputError
from rtcohand_drake.data.hand_features import FINGER_CHAINS
from rtcohand_drake.analysis.inspection import measure_inspection
from rtcohand_drake.stations.kinematic_workpiece import KinematicWorkpiece
from rtcohand_drake.systems.gestures.simulated_person import (
    PersonConfig,
    SimulatedPerson,
    make_builtin_person,
    population_user_ids,
)
from rtcohand_drake.scenario import load_scenario
from rtcohand_drake.cell.plant import eye_position
from rtcohand_drake.interfaces import GESTURE_FEATURES, INTENDED_TWIST, POLICY_MEAN, RESUME_COUNT, WORKPIECE_POSE

# The workpiece upright in the mold (world), as the simulated station starts.
MOLD_POSE_W = np.array([0.4501, -0.1201, 0.0819, 0.70679, 0.70743, 0.0002, 0.0])
OUT_SAMPLE = [u for u, g in population_user_ids().items() if g == "out-sample"]


@pytest.fixture(scope="module")
def scenario():
    return load_scenario("inspection")


@pytest.fixture(scope="module")
def eye_W(scenario):
    return eye_position(scenario.cell)


def _user(user_id: str, config: GeneratorConfig | None = None):
    config = config or GeneratorConfig()
    index = int(user_id[1:])
    return simulate_user(config, index, user_groups(15, config)[index], 0)


def _operator(scenario, eye_W, user_id, seed=0, generator=None):
    profile, clips, _ = _user(user_id)
    op = SimulatedPerson(profile, scenario.cell.user_frame.to_rigid_transform(), eye_W,
                           generator=generator, rate_hz=scenario.policy.rate_hz, seed=seed)
    return op, clips


def _run_fixed_pose(op, duration_s, pose_W=MOLD_POSE_W):
    """The operator watching a part that does not move; logs features, keypoints, intent."""
    builder = DiagramBuilder()
    op = builder.AddSystem(op)
    pose = builder.AddSystem(ConstantVectorSource(np.asarray(pose_W, float)))
    builder.Connect(pose.get_output_port(), op.GetInputPort(WORKPIECE_POSE))
    period = op.period_s
    logs = {name: LogVectorOutput(op.GetOutputPort(name), builder, period)
            for name in ("gesture_features", "gesture_status", "keypoints", "intended_twist")}
    simulator = Simulator(builder.Build())
    simulator.AdvanceTo(duration_s)
    root = simulator.get_context()
    return {name: log.FindLog(root).data().T.copy() for name, log in logs.items()}


def _run_kinematic_loop(scenario, op, duration_s):
    """The operator's intended twist moves the part exactly: the task as the person means it."""
    builder = DiagramBuilder()
    op = builder.AddSystem(op)
    part = builder.AddSystem(KinematicWorkpiece(scenario.cell.user_frame.to_rigid_transform(), MOLD_POSE_W))
    builder.Connect(op.GetOutputPort(INTENDED_TWIST), part.GetInputPort("twist"))
    builder.Connect(part.GetOutputPort(WORKPIECE_POSE), op.GetInputPort(WORKPIECE_POSE))
    log = LogVectorOutput(part.GetOutputPort(WORKPIECE_POSE), builder, 0.02)
    simulator = Simulator(builder.Build())
    phases = []

    def watch(root):
        phase = op.person_state(op.GetMyContextFromRoot(root)).phase
        if not phases or phases[-1] != phase:
            phases.append(phase)

    simulator.set_monitor(lambda root: watch(root))
    simulator.AdvanceTo(duration_s)
    data = log.FindLog(simulator.get_context())
    return data.sample_times().copy(), data.data().T.copy(), phases, op.person_state(
        op.GetMyContextFromRoot(simulator.get_context()))


def test_hand_is_anatomical(scenario, eye_W):
    clean = replace(GeneratorConfig(), jitter_m=0.0)
    op, _ = _operator(scenario, eye_W, "u12", generator=clean)  # uncurls for +Tz, turns while moving for Rx
    kp = _run_fixed_pose(op, 8.0)["keypoints"].reshape(-1, 21, 3)
    seen = np.isfinite(kp).all(axis=(1, 2))
    assert seen.sum() > 40 and (~seen).sum() > 0  # gestures, and the hand lowered out of view between them
    kp = kp[seen]
    bones = [(0, int(ch[0])) for ch in FINGER_CHAINS] + [
        (int(ch[i]), int(ch[i + 1])) for ch in FINGER_CHAINS for i in range(3)]
    lengths = np.stack([np.linalg.norm(kp[:, a] - kp[:, b], axis=1) for a, b in bones], axis=1)
    np.testing.assert_allclose(lengths, np.broadcast_to(lengths[0], lengths.shape), atol=1e-9)
    # The same hand as that user's dataset clips.
    _, _, truths = _user("u12")
    ref = truths[0].keypoints_clean[0]
    np.testing.assert_allclose(lengths[0], [np.linalg.norm(ref[a] - ref[b]) for a, b in bones], atol=1e-9)
    # It starts in the reference gesture: palm down, where that user's clips start.
    n = np.cross(kp[0, 5] - kp[0, 17], kp[0, 9] - kp[0, 0])
    assert n[2] / np.linalg.norm(n) < -0.95
    assert np.abs(kp[0] - ref).max() < 0.015


def _signature(features: np.ndarray) -> np.ndarray:
    """Feature statistics of a gesture, per feature: mean, mean magnitude, and mean of x |x|
    (which stroke of a back-and-forth gesture is the fast one)."""
    return np.concatenate([features.mean(axis=0), np.abs(features).mean(axis=0),
                           (features * np.abs(features)).mean(axis=0)])


@pytest.mark.parametrize("user_id", OUT_SAMPLE)
def test_lift_gesture_is_that_users_plus_tz(scenario, eye_W, user_id):
    """A part sitting in the mold: the operator wants to lift it and makes that user's +Tz gesture.

    Its feature statistics during the gesture are nearest to the user's own +Tz
    clips among all of the user's one-motion clips (12 motions, 2 clips each).
    """
    op, clips = _operator(scenario, eye_W, user_id)
    out = _run_fixed_pose(op, 10.0)
    intent = out["intended_twist"]
    assert np.all(intent[:, [0, 1, 3, 4, 5]] == 0.0) and intent[:, 2].max() > 0.05  # straight up, nothing else
    active = intent[:, 2] > 0.5 * intent[:, 2].max()
    mine = _signature(out["gesture_features"][active])
    refs, names = [], []
    for clip in clips:
        if len(clip.active_dims) != 1:
            continue
        pc = to_policy_clip(clip, scenario.policy.rate_hz)
        dim = int(clip.active_dims[0])
        on = np.abs(pc.labels[:, dim]) > 0.5 * np.abs(pc.labels[:, dim]).max()
        # The handler reacts late: take the gesture's own window, the labels' shifted back 0.3 s.
        on = np.roll(on, -3) & pc.valid
        refs.append(_signature(pc.features[on]))
        names.append(clip.clip_id.split("_", 1)[1])
    refs = np.array(refs)
    scale = refs.std(axis=0) + 1e-6
    distance = np.linalg.norm((refs - mine) / scale, axis=1)
    order = np.argsort(distance)
    assert names[order[0]] == "Tz+", ([names[k] for k in order[:3]], op.user.gestures[(2, 1)].describe())
    other = min(distance[k] for k in order if names[k] != "Tz+")
    assert other > 1.3 * distance[order[0]]


def test_task_progresses_lift_inspect(scenario, eye_W):
    """By default the part is shown where the lift ends: the presentation is reached with it."""
    op, _ = _operator(scenario, eye_W, OUT_SAMPLE[0])
    times, poses, phases, state = _run_kinematic_loop(scenario, op, 120.0)
    assert phases == ["lift", "inspect", "done"]
    assert state.seen.all()
    result = measure_inspection(times, poses, eye_W)
    assert result.completed and result.faces_inspected == 6 and result.completion_time < 120.0
    # Straight up out of the mold: nothing sideways until the part is clear of it.
    low = poses[:, 2] < MOLD_POSE_W[2] + 0.06
    assert np.abs(poses[low, :2] - MOLD_POSE_W[:2]).max() < 1e-6
    # Shown straight above the mold, in the workspace box and well clear of the glass (world y = 0.52).
    final = poses[-1, :3]
    assert scenario.workspace.contains(final) and final[1] < 0.35
    assert np.linalg.norm(final[:2] - MOLD_POSE_W[:2]) < PersonConfig().drift_tolerance_m


def test_a_presentation_point_elsewhere_is_reached_before_the_turns(scenario, eye_W):
    profile, _, _ = _user(OUT_SAMPLE[0])
    point_W = (0.25, 0.15, 0.50)
    op = SimulatedPerson(profile, scenario.cell.user_frame.to_rigid_transform(), eye_W,
                         PersonConfig(presentation_xyz_W=point_W), rate_hz=scenario.policy.rate_hz)
    times, poses, phases, state = _run_kinematic_loop(scenario, op, 25.0)
    assert phases[:3] == ["lift", "present", "inspect"]
    entered = min(k for k, p in enumerate(poses) if np.linalg.norm(p[:3] - point_W) < PersonConfig().presentation_tolerance_m)
    assert times[entered] < 25.0


def test_deterministic_for_a_seed(scenario, eye_W):
    runs = [_run_fixed_pose(_operator(scenario, eye_W, "u11", seed=s)[0], 4.0) for s in (3, 3, 4)]
    np.testing.assert_array_equal(runs[0]["gesture_features"], runs[1]["gesture_features"])
    np.testing.assert_array_equal(runs[0]["keypoints"], runs[1]["keypoints"])
    assert not np.array_equal(runs[0]["gesture_features"], runs[2]["gesture_features"])


def test_builtin_operator_is_an_out_sample_user_with_own_context(scenario):
    op, pieces = make_builtin_person(scenario, seed=0)
    assert op.user.group == "out-sample" and op.user.user_id == OUT_SAMPLE[0]
    assert len(pieces) == 72
    assert all(x.shape[1] == 36 and y.shape == (len(x), 6) for x, y in pieces)
    assert op.HasInputPort(WORKPIECE_POSE) and op.HasOutputPort(INTENDED_TWIST)
    # The context is that user's clips as the generator writes them.
    _, clips, _ = _user(OUT_SAMPLE[0])
    pc = to_policy_clip(clips[5], scenario.policy.rate_hz)
    np.testing.assert_array_equal(pieces[5][0], pc.features)
    np.testing.assert_array_equal(pieces[5][1], pc.labels)
    other, _ = make_builtin_person(scenario, user="u03")
    assert other.user.user_id == "u03" and other.user.group == "in-sample"


def test_unknown_user_is_one_line_error(scenario):
    with pytest.raises(InputError) as err:
        make_builtin_person(scenario, user="alice")
    message = str(err.value)
    assert "\n" not in message and "alice" in message and "u00" in message and "u14" in message


def test_intent_policy_passes_the_intended_twist_on_late():
    from pydrake.systems.analysis import Simulator

    from rtcohand_drake.analysis.reference_policies import IntentPolicy

    policy = IntentPolicy(rate_hz=10.0, delay_s=0.3)
    ctx = policy.CreateDefaultContext()
    sim = Simulator(policy, ctx)
    policy.GetInputPort(GESTURE_FEATURES).FixValue(ctx, np.zeros(36))
    policy.GetInputPort(RESUME_COUNT).FixValue(ctx, [0.0])
    seen = []
    for k in range(8):
        policy.GetInputPort(INTENDED_TWIST).FixValue(ctx, [0.01 * (k + 1), 0, 0, 0, 0, np.nan])
        sim.AdvanceTo(0.1 * k + 0.05)
        seen.append(policy.GetOutputPort(POLICY_MEAN).Eval(ctx).copy())
    seen = np.array(seen)
    # Sampled at t = 0.1 k; read out 3 periods (0.3 s) later; a NaN intent reads as zero.
    assert np.allclose(seen[3:, 0], 0.01 * np.arange(1, 6)) and np.allclose(seen[:3], 0.0)
    assert np.all(np.isfinite(seen))


def test_intent_reference_run_stops_a_hold_after_the_sixth_face():
    """The shared intent-reference run (the study's and bench_inspection's): the person's own intent
    in place of the policy finishes the task, and with stop_when_done the run ends done_hold_s later."""
    from rtcohand_drake.analysis.reference_policies import run_intent_reference
    from rtcohand_drake.scenario import load_scenario

    scenario = load_scenario("inspection")
    log = run_intent_reference(scenario, "u12", seed=0, population_seed=0, stop_when_done=True)
    assert log.completed and log.faces_inspected == 6
    assert abs(log.extra_attrs["sim_duration_s"] - log.completion_time - scenario.done_hold_s) <= 0.05
    assert log.extra_attrs["seed"] == 0


def test_the_builtin_person_comes_from_a_population_drawn_with_other_settings(scenario):
    """`make_builtin_person(..., generator=...)`: the person and context of a population drawn with other
    generator settings (as `data.generate --direct-share 1 --repeated-rhythm-share 0` draws it), which
    the closed-loop benchmark's `--direct-share` runs; the default population's person is unchanged."""
    direct = replace(GeneratorConfig(), p_direct=1.0, p_repeated_rhythm=0.0)
    person, pieces = make_builtin_person(scenario, user="u10", population_seed=0, generator=direct)
    profile, clips, _ = simulate_user(direct, 10, user_groups(15, direct)[10], 0)
    pc = to_policy_clip(clips[3], scenario.policy.rate_hz)
    np.testing.assert_array_equal(pieces[3][0], pc.features)
    np.testing.assert_array_equal(pieces[3][1], pc.labels)
    assert person.generator is direct and person.user.user_id == profile.user_id == "u10"
    _, default_pieces = make_builtin_person(scenario, user="u10", population_seed=0)
    assert not np.array_equal(default_pieces[3][1], pieces[3][1]) or not np.array_equal(default_pieces[3][0], pieces[3][0])
