"""The recorded person: held-out repetitions for the motion asked for, joined without a jump; a
missing motion as a one-line error; the wrong-way and drift shares against a written-out count.

The dataset files are written here, in the importer's layout (`data.import_shrec17`): per person
and motion, repetitions of a one-motion gesture, the last held out (`split = test`), each with its
first and last frame held still for 0.5 s around the labelled gesture.
"""

from __future__ import annotations

import numpy as np
import pytest
from pydrake.math import RigidTransform, RollPitchYaw
from pydrake.systems.analysis import Simulator
from pydrake.systems.framework import DiagramBuilder
from pydrake.systems.primitives import LogVectorOutput

from rtcohand_drake.analysis.gesture_following import FULL_COMMAND, following_shares, stuck_motion, workpiece_twist_U
from rtcohand_drake.cell.geometry import matrix_to_quaternion
from rtcohand_drake.cell.plant import eye_position
from rtcohand_drake.data.dataset import Clip, write_dataset
from rtcohand_drake.errors import run_cli
from rtcohand_drake.interfaces import INTENDED_TWIST, KEYPOINTS, WORKPIECE_POSE
from rtcohand_drake.scenario import load_scenario
from rtcohand_drake.stations.kinematic_workpiece import KinematicWorkpiece
from rtcohand_drake.systems.gestures.recorded_person import (MOTIONS, PALM, RecordedPerson, load_recorded_person,
                                                             motion_name)

FPS = 30.0
REST = 15  # frames held still before and after the gesture, as the importer does (0.5 s)
MOLD_POSE_W = np.array([0.4501, -0.1201, 0.0819, 0.70679, 0.70743, 0.0002, 0.0])


def _hand(scale: float) -> np.ndarray:
    """(21, 3) a flat right hand in U, palm down; `scale` sets its size (each clip its own)."""
    points = [[0.0, 0.0, 0.0]]
    for f, x in enumerate((-0.045, -0.02, 0.0, 0.02, 0.04)):
        for j in range(4):
            points.append([x * (1.0 + 0.2 * j) - (0.02 if f == 0 else 0.0), 0.07 + 0.025 * j, 0.004 * j * (f + 1)])
    return scale * np.asarray(points)


def _clip(user: str, motion, essai: int, split: str, scale: float, n: int = 24) -> Clip:
    """One repetition: the hand sweeps 0.2 m along axis `dim mod 3`, labelled with the motion's full
    command over the gesture, zero over the held rests."""
    dim, sign = motion
    u = np.sin(0.5 * np.pi * np.linspace(0.0, 1.0, n)) ** 2
    direction = np.eye(3)[dim % 3] * sign
    gesture = _hand(scale)[None] + 0.2 * u[:, None, None] * direction + np.array([0.0, 0.3, 0.1])
    keypoints = np.concatenate([np.repeat(gesture[:1], REST, 0), gesture, np.repeat(gesture[-1:], REST, 0)])
    labels = np.zeros((len(keypoints), 6))
    labels[REST:REST + n, dim] = sign * FULL_COMMAND[dim]
    return Clip(user=user, clip_id=f"{motion_name(motion)}e{essai}", group="out-sample", split=split,
                active_dims=np.array([dim]), fps=FPS, keypoints=keypoints.astype(np.float32),
                object_velocity=labels.astype(np.float32))


def _scale(person: int, motion_index: int, essai: int) -> float:
    return 1.0 + 0.01 * (person * 50 + motion_index * 4 + essai)


def write_people(path, skip: dict | None = None):
    """Person p1 has every motion (three repetitions; Tz+ two held out, the others one); p2 has no
    held-out repetition of the motions in `skip["p2"]`."""
    skip = skip or {}
    clips = []
    for i, person in enumerate(("p1", "p2")):
        for m, motion in enumerate(MOTIONS):
            for e in (1, 2, 3):
                split = "test" if e == 3 or (motion == (2, 1) and e == 2) else "train"
                if split == "test" and motion_name(motion) in skip.get(person, ()):
                    continue
                clips.append(_clip(person, motion, e, split, _scale(i, m, e)))
    write_dataset(path, clips)
    return path


@pytest.fixture(scope="module")
def people(tmp_path_factory):
    return write_people(tmp_path_factory.mktemp("recorded") / "people.h5", {"p2": ("Tz+",)})


@pytest.fixture(scope="module")
def scenario():
    return load_scenario("inspection")


def _shape(kp: np.ndarray) -> np.ndarray:
    return kp - kp[list(PALM)].mean(axis=0)


def _run_kinematic(scenario, person, duration_s: float):
    """The recorded person with a part that follows their intended twist exactly; logs keypoints and
    intent, and the motion of the stroke at each sample."""
    builder = DiagramBuilder()
    source = builder.AddSystem(person)
    part = builder.AddSystem(KinematicWorkpiece(scenario.cell.user_frame.to_rigid_transform(), MOLD_POSE_W))
    builder.Connect(source.GetOutputPort(INTENDED_TWIST), part.GetInputPort("twist"))
    builder.Connect(part.GetOutputPort(WORKPIECE_POSE), source.GetInputPort(WORKPIECE_POSE))
    logs = {name: LogVectorOutput(source.GetOutputPort(name), builder, source.period_s)
            for name in (KEYPOINTS, INTENDED_TWIST)}
    simulator = Simulator(builder.Build())
    asked = []
    simulator.set_monitor(lambda root: asked.append(
        (root.get_time(), getattr(person.person_state(person.GetMyContextFromRoot(root)).stroke, "motions", None))))
    simulator.AdvanceTo(duration_s)
    root = simulator.get_context()
    out = {name: log.FindLog(root).data().T.copy() for name, log in logs.items()}
    out["time"] = logs[KEYPOINTS].FindLog(root).sample_times().copy()
    return out, asked


@pytest.fixture(scope="module")
def kinematic_run(people, scenario):
    recordings = load_recorded_person(people, "p1", scenario.policy.rate_hz)
    person = RecordedPerson(recordings, scenario.cell.user_frame.to_rigid_transform(), eye_position(scenario.cell),
                            rate_hz=scenario.policy.rate_hz, seed=3)
    return _run_kinematic(scenario, person, 40.0)


def test_plays_held_out_repetitions_of_the_motion_asked_for_never_context(people, kinematic_run):
    from rtcohand_drake.data.dataset import read_dataset

    log, asked = kinematic_run
    clips = [c for c in read_dataset(people) if c.user == "p1"]
    frames, owners = [], []
    for c in clips:
        for kp in c.keypoints[REST:-REST]:
            frames.append(_shape(kp.astype(float)).reshape(-1))
            owners.append(c)
    frames = np.asarray(frames)
    played = set()
    intent_at, last = {}, None
    for t, motions in asked:  # the stroke asked for at each time (the last, once it has ended)
        last = motions if motions is not None else last
        intent_at[round(t, 6)] = last
    n_played = 0
    for t, kp, a in zip(log["time"], log[KEYPOINTS], log[INTENDED_TWIST]):
        if not np.any(a):
            continue  # at rest, or taking a recording's first shape
        n_played += 1
        distance = np.linalg.norm(frames - _shape(kp.reshape(21, 3)).reshape(-1), axis=1)
        owner = owners[int(np.argmin(distance))]
        assert distance.min() < 1e-3, f"t={t:.1f}: the hand is no recorded frame"
        assert owner.split == "test", f"t={t:.1f}: played {owner.name}, a context clip"
        dim = int(np.argmax(np.abs(a)))
        motion = (dim, int(np.sign(a[dim])))
        assert (int(owner.active_dims[0]), int(np.sign(owner.object_velocity.sum(0)[owner.active_dims[0]]))) == motion
        assert intent_at[round(t, 6)] is not None and tuple(intent_at[round(t, 6)][0]) == motion, \
            f"t={t:.1f}: played {motion_name(motion)}, asked {intent_at[round(t, 6)]}"
        played.add(owner.name)
    assert n_played > 100
    # The lift takes both held-out repetitions of Tz+ in turn; the inspection asks for turns too.
    assert {"p1/Tz+e2", "p1/Tz+e3"} <= played
    assert any(name.split("/")[1][:2] in ("Rx", "Ry", "Rz") for name in played)


def test_consecutive_recordings_join_without_a_jump(kinematic_run):
    log, _ = kinematic_run
    kp = log[KEYPOINTS].reshape(-1, 21, 3)
    ok = np.all(np.isfinite(kp), axis=(1, 2))
    steps = np.linalg.norm(np.diff(kp, axis=0), axis=2).max(axis=1)[ok[1:] & ok[:-1]]
    # Within a recording the hand moves at most 0.2 m * (pi/2) / 23 frames * 3 frames a period (about
    # 41 mm); a recording played where it was recorded would jump by up to 0.2 m (from the end of one
    # sweep back to the start of the next) and by the change of hand size.
    assert steps.max() < 0.045
    intent = np.any(log[INTENDED_TWIST] != 0, axis=1)
    starts = np.flatnonzero(intent[1:] & ~intent[:-1]) + 1
    assert len(starts) >= 5
    for k in starts:  # each recording starts where the hand, having taken its first shape, is
        palm = kp[:, list(PALM)].mean(axis=1)
        assert np.linalg.norm(palm[k] - palm[k - 1]) < 1e-9


def test_a_motion_without_a_held_out_recording_is_a_one_line_error(people, capsys):
    from rtcohand_drake.run import main

    status = run_cli(main, ["--gesture-source", "recorded", "--gesture-file", str(people), "--clip", "p2",
                            "--no-meshcat", "--realtime-rate", "0", "--duration", "3"], prog="rtcohand_drake.run")
    err = capsys.readouterr().err.strip().splitlines()
    assert status == 2
    assert "Tz+" in err[-1] and "'p2'" in err[-1] and str(people) in err[-1]
    assert err[-1].startswith("rtcohand_drake.run: error: ")


def test_unknown_person_is_a_one_line_error(people, scenario):
    from rtcohand_drake.errors import InputError

    with pytest.raises(InputError, match="no person named 'p9'"):
        load_recorded_person(people, "p9", scenario.policy.rate_hz)


def test_wrong_way_and_drift_shares_against_a_written_out_count():
    # Intended twist at 10 Hz: Tx+ from 1.0 to 2.0 s, Rz- from 3.0 to 4.0 s, rest otherwise; run to 6 s.
    intent_t = np.arange(0.0, 6.0, 0.1)
    intent = np.zeros((len(intent_t), 6))
    intent[(intent_t >= 1.0 - 1e-9) & (intent_t < 2.0 - 1e-9), 0] = 0.12
    intent[(intent_t >= 3.0 - 1e-9) & (intent_t < 4.0 - 1e-9), 5] = -0.3
    # The part's twist at 50 Hz.
    t = np.arange(0.0, 6.0, 0.02) + 0.01
    twist = np.zeros((len(t), 6))
    twist[(t > 1.0) & (t < 1.3), 0] = -0.05  # against Tx+: -0.05 / 0.12 = -0.42 of a full command
    twist[(t > 1.3) & (t < 2.0), 0] = 0.10
    twist[(t > 3.0) & (t < 3.2), 5] = 0.10  # against Rz-: 0.1 / 0.6 = 0.17 < 0.2, not wrong way
    twist[(t > 3.2) & (t < 3.4), 5] = 0.20  # 0.33 of a full command against it: wrong way
    twist[(t > 2.1) & (t < 2.4), 1] = 0.05  # still moving 0.1-0.4 s after Tx+: not yet rest
    twist[(t > 4.6) & (t < 4.8), 4] = 0.15  # rest drift about Y: 0.25 of a full command
    twist[(t > 5.0) & (t < 5.2), 2] = 0.02  # 0.17 of a full command: not drift
    wrong, drift = following_shares(t, twist, intent_t, intent)
    # Written out: gesture samples are those in [1.0, 2.0) and [3.0, 4.0) (50 each); wrong way: 15
    # (1.01 .. 1.29) + 10 (3.21 .. 3.39). Rest: from 0.5 s after the start (0.51 .. 0.99: 25), 0.5 s
    # after each gesture's end (2.51 .. 2.99: 25; 4.51 .. 5.99: 75); drift: 10 (4.61 .. 4.79).
    assert wrong == pytest.approx(25 / 100)
    assert drift == pytest.approx(10 / 125)


def test_the_motion_a_run_is_stuck_on_against_a_written_out_count():
    # Intended twist at 10 Hz over 100 s: Ty+ (0.12 m/s) in 40-46 s and 70-100 s, Rz- (0.6 rad/s) in 50-60 s,
    # rest otherwise; the policy's output at 10 Hz, 50 ms after each intent sample: 0.012 m/s along Ty in
    # the Ty+ spans (a tenth of the gesture), -0.3 rad/s about Z in the Rz- span.
    t = np.arange(0.0, 100.0, 0.1)
    intended = np.zeros((len(t), 6))
    ty = ((t >= 40.0 - 1e-9) & (t < 46.0 - 1e-9)) | (t >= 70.0 - 1e-9)
    rz = (t >= 50.0 - 1e-9) & (t < 60.0 - 1e-9)
    intended[ty, 1], intended[rz, 5] = 0.12, -0.6
    mean = np.zeros_like(intended)
    mean[ty, 1], mean[rz, 5] = 0.012, -0.3
    stuck = stuck_motion(t, intended, t + 0.05, mean)
    # Written out: the last 60 s are the samples after 39.9 s (600 of them); Ty+ in 40-46 s (60) and
    # 70-100 s (300), Rz- in 50-60 s (100). Ty+ is gestured most: 360 / 600 of the time. The output held at
    # each sample is the one 50 ms before it (the previous sample's): over the Ty+ samples it is 0.012
    # except at the first sample of each span (two samples read 0), so the gain is 358 x 0.012 x 0.12 /
    # (360 x 0.12^2).
    assert stuck["motion"] == "Ty+"
    assert stuck["time_share"] == pytest.approx(360 / 600)
    assert stuck["gain"] == pytest.approx(358 * 0.012 * 0.12 / (360 * 0.12 ** 2))
    assert stuck_motion(t, np.zeros_like(intended), t, mean) is None  # no gesture in the last 60 s


def test_workpiece_twist_in_the_user_frame():
    R_WU = RollPitchYaw(0.0, 0.0, np.pi / 2).ToRotationMatrix().matrix()  # U turned a quarter about Z
    t = np.arange(0.0, 1.0, 0.02)
    v_U, w_U = np.array([0.1, 0.0, 0.0]), np.array([0.0, 0.0, 0.5])
    poses = []
    for tk in t:
        X = RigidTransform(RollPitchYaw(0.0, 0.0, w_U[2] * tk).ToRotationMatrix(), R_WU @ v_U * tk)
        poses.append(np.r_[X.translation(), matrix_to_quaternion(X.rotation().matrix())])
    mid, twist = workpiece_twist_U(t, np.asarray(poses), R_WU)
    assert np.allclose(mid, t[:-1] + 0.01)
    assert np.allclose(twist, np.r_[v_U, w_U], atol=1e-9)


def test_study_of_recorded_people_writes_each_run_with_its_shares(people, tmp_path):
    import json

    from rtcohand_drake.analysis import study

    out = tmp_path / "study"
    status = study.main(["--recorded-people", str(people), "--people", "p1", "p2", "--cap", "6", "--workers", "0",
                         "--out", str(out)])
    assert status == 1  # p2 has no held-out Tz+, which the lift asks for at once
    data = json.loads((out / "study.json").read_text())
    assert data["conditions"] == ["responsive", "intent"]
    for condition in ("responsive", "intent"):
        run = data["results"]["p1"][condition]["0"]
        assert run["completed"] is False and run["faces"] < 6  # capped at 6 s
        assert run["contacts"] == 0 and run["limits_exceeded"] == []
        assert 0.0 <= run["wrong_way_share"] <= 1.0 and 0.0 <= run["drift_share"] <= 1.0
        assert run["stuck"]["motion"][:2] in ("Tx", "Ty", "Tz", "Rx", "Ry", "Rz")  # not done: what it was asking for
        assert 0.0 < run["stuck"]["time_share"] <= 1.0
        assert data["results"]["p2"][condition]["0"] is None
    assert sorted(p.name for p in (out / "logs").glob("p1_*.h5")) == ["p1_intent_s0.h5", "p1_responsive_s0.h5"]
    text = (out / "study.md").read_text()
    assert "no held-out recording (split test) of Tz+" in text and "| p1 | intent | 0 |" in text
    assert f"- p1 responsive run seed 0: {data['results']['p1']['responsive']['0']['stuck']['motion']} (" in text


def test_study_of_recorded_people_runs_the_scenario_given(people, tmp_path):
    import json

    import yaml

    from rtcohand_drake.analysis import study
    from rtcohand_drake.scenario import ScenarioError, resolve_scenario_path

    data = yaml.safe_load(resolve_scenario_path("inspection").read_text())
    data["duration_s"] = 4.0
    mine = tmp_path / "mine.yaml"
    mine.write_text(yaml.safe_dump(data, sort_keys=False))
    out = tmp_path / "study"
    status = study.main(["--recorded-people", str(people), "--people", "p1", "--conditions", "responsive",
                         "--scenario", str(mine), "--workers", "0", "--out", str(out)])
    assert status == 0
    summary = json.loads((out / "study.json").read_text())
    assert summary["scenario"] == str(mine) and summary["cap_s"] == 4.0  # the cap is the scenario's
    from rtcohand_drake.run_log import read_run_log

    log = read_run_log(out / "logs" / "p1_responsive_s0.h5")
    assert log.command_time[-1] <= 4.0 + 1e-6  # the run stopped at the scenario's duration
    assert f"scenario {mine}" in (out / "study.md").read_text()
    (tmp_path / "bad.yaml").write_text("duration_s: [\n")
    with pytest.raises(ScenarioError):
        study.main(["--recorded-people", str(people), "--scenario", str(tmp_path / "bad.yaml"), "--workers", "0",
                    "--out", str(out)])
    from rtcohand_drake.errors import InputError

    with pytest.raises(InputError, match="go with --recorded-people"):  # only with --recorded-people
        study.main(["--scenario", str(mine), "--out", str(out)])
