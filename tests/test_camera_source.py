"""The camera gesture source: MediaPipe on drawn hands, the metric fit into U, a video through the whole diagram.

The drawn hand (`rtcohand_drake.vision.drawn_hand`) is the offline test image:
its keypoints are known, so the tracker's landmarks can be checked against them.
"""

import math
import socket
import subprocess
import sys

import h5py
import numpy as np
import pytest

from rtcohand_drake.errors import InputError
from rtcohand_drake.vision.calibration import CameraCalibration, load_calibration
from rtcohand_drake.vision.config import Camera
from rtcohand_drake.vision.drawn_hand import background, draw_hand, drawn_hand_frames, open_hand_U, project, write_video
from rtcohand_drake.vision.hand_pose import choose_hand, keypoints_in_user_frame
from rtcohand_drake.vision.landmarker import HandDetection, HandLandmarker, model_path

CALIBRATION = CameraCalibration()


@pytest.fixture()
def no_network(monkeypatch):
    def refuse(*args, **kwargs):
        raise OSError("network access in a test that must run offline")

    monkeypatch.setattr(socket.socket, "connect", refuse)
    monkeypatch.setattr(socket, "create_connection", refuse)


@pytest.fixture(scope="module")
def landmarker():
    # MediaPipe's accuracy on a noiseless drawing: the scenario's light blur, meant for real footage's
    # pixel noise (docs/own_hand.md), moves one drawn pose's landmarks from 12 to 22 px (median).
    with HandLandmarker(Camera(blur_sigma_px=0.0), video=False) as lm:
        yield lm


def _drawn(wrist_U):
    keypoints_U = open_hand_U(wrist_U, curl=0.1)
    points_px = project((keypoints_U - CALIBRATION.p_UC()) @ CALIBRATION.R_UC(), CALIBRATION.camera_matrix())
    return draw_hand(background(640, 480), points_px), points_px, keypoints_U


def test_detector_loads_from_the_installed_package_offline(no_network):
    from rtcohand_drake.cell.robot_files import models_dir

    assert model_path().is_file() and model_path().parent.parent == models_dir()
    with HandLandmarker(video=False) as lm:
        assert lm.detect(background(640, 480)) == []  # loads, runs, and sees no hand in an empty picture
        image, _, _ = _drawn((0.0, 0.2, 0.0))
        assert len(lm.detect(image)) == 1


@pytest.mark.parametrize("wrist_U", [(0.0, 0.2, 0.0), (0.0, 0.2, -0.03), (0.0, 0.1, 0.0)])
def test_drawn_hand_detected_within_tolerance(landmarker, wrist_U):
    image, points_px, keypoints_U = _drawn(wrist_U)
    hands = landmarker.detect(image)
    assert len(hands) == 1
    hand = hands[0]
    # Landmarks: median within 5 % of the hand's size (about half a finger's width): the drawing puts
    # joints at capsule ends, MediaPipe at anatomical joints; 9-13 px was seen at 290-490 px.
    size = hand.size_px
    assert 200 < size < 450
    assert np.median(np.linalg.norm(hand.image_px - points_px, axis=1)) < 0.05 * size
    # Metric keypoints in U: MediaPipe's generic hand is somewhat larger than the drawn one, so depth
    # carries that scale error; the hand's centre is within 3 cm, its points within 4 cm (median).
    est = keypoints_in_user_frame(hand, CALIBRATION, (640, 480))
    assert np.linalg.norm(est.mean(axis=0) - keypoints_U.mean(axis=0)) < 0.03
    assert np.median(np.linalg.norm(est - keypoints_U, axis=1)) < 0.04
    # The hand is upright in U (fingers up +Z, the palm's width along X), as drawn.
    assert est[12, 2] - est[0, 2] > 0.12
    assert abs(est[5, 0] - est[17, 0]) > 0.04


def _fake(handedness, size_px, score=0.9):
    image = np.array([[0.0, 0.0], [size_px, 0.0]] + [[size_px / 2, size_px / 2]] * 19)
    return HandDetection(image, np.zeros((21, 3)), handedness, score)


def test_choose_hand_rule():
    small_right, big_left = _fake("Left", 100), _fake("Right", 300)  # not mirrored: "Left" is the right hand
    assert choose_hand([], Camera()) is None
    assert choose_hand([big_left, small_right], Camera()) is small_right
    assert choose_hand([big_left, small_right], Camera(mirrored=True)) is big_left
    assert choose_hand([big_left, small_right], Camera(hand="left")) is big_left
    assert choose_hand([big_left, small_right], Camera(hand="largest")) is big_left
    # No right hand seen: the largest one.
    assert choose_hand([_fake("Right", 100), big_left], Camera()) is big_left


def test_calibration_file(tmp_path):
    good = tmp_path / "cam.yaml"
    good.write_text("image_size_px: [1280, 720]\nfocal_length_px: [900, 900]\ncamera_position_m: [0, 0.6, 0]\n")
    calib = load_calibration(good)
    K = calib.camera_matrix((640, 360))
    assert K[0, 0] == pytest.approx(450) and K[0, 2] == pytest.approx(320) and K[1, 2] == pytest.approx(180)
    # The default pose looks along -Y of U, image right is the person's left (-X), image down is -Z.
    R = CameraCalibration().R_UC()
    assert np.allclose(R[:, 2], [0, -1, 0], atol=1e-9) and np.allclose(R[:, 0], [-1, 0, 0], atol=1e-9)
    for text, fragment in [("focal_lenght_px: [1, 1]\n", "unknown key"), ("distortion: [1, 2]\n", "distortion"),
                           ("image_size_px: [0, 480]\n", "positive"), (": [\n", "YAML")]:
        bad = tmp_path / "bad.yaml"
        bad.write_text(text)
        with pytest.raises(InputError, match=fragment) as err:
            load_calibration(bad)
        assert str(bad) in str(err.value)
    with pytest.raises(InputError, match="no such"):
        load_calibration(tmp_path / "none.yaml")


# A drawn hand waves, makes the pause sign (a thumbs-up) twice, waves, and leaves the picture.
# The drawing jumps from one pose to the next, where the tracker may lose it for a frame, so
# validity is checked while it waves first.
SCRIPT = [("wave", 2.5), ("thumbs_up", 1.0), ("wave", 1.0), ("thumbs_up", 1.0), ("wave", 0.5), ("gone", 1.2)]
WAVE_S, SIGN_S, LEAVES_S = 2.5, (2.5, 4.5), 6.0


@pytest.fixture(scope="module")
def hand_video(tmp_path_factory):
    path = tmp_path_factory.mktemp("video") / "drawn_hand.avi"
    assert write_video(path, (f for f, _ in drawn_hand_frames(CALIBRATION, SCRIPT))) == 216
    return path


@pytest.fixture(scope="module")
def context_file(tmp_path_factory):
    from rtcohand_drake.data.dataset import write_dataset
    from rtcohand_drake.data.population import GeneratorConfig, generate_population

    path = tmp_path_factory.mktemp("data") / "me.h5"
    write_dataset(path, generate_population(GeneratorConfig(), n_users=1, seed=1)[:12])
    return path


def test_drawn_hand_video_through_the_whole_diagram(tmp_path, hand_video, context_file, capsys):
    from rtcohand_drake.run import main
    from rtcohand_drake.run_log import read_run_log

    log_path = tmp_path / "run.h5"
    assert main(["--scenario", "inspection", "--gesture-source", "camera", "--video", str(hand_video),
                 "--context-file", str(context_file), "--realtime-rate", "0", "--no-meshcat",
                 "--log", str(log_path)]) == 0
    printed = capsys.readouterr()
    assert "defaults for a webcam" in printed.err
    assert "gesture source camera, policy cchp_path_shape.pt:" in printed.out  # the run says which file read the hand
    log = read_run_log(log_path)
    assert log.gesture_source == "camera" and log.model.endswith("cchp_path_shape.pt")  # a real hand's file, no --model
    t, valid, kp = log.gesture_time, log.gesture_valid, log.gesture_keypoints
    assert kp.shape == (len(t), 63) and len(t) >= 72  # the run ends with the video (7.2 s at 10 Hz)
    waving = (t >= 0.3) & (t < WAVE_S)
    assert valid[waving].mean() >= 0.9
    in_view = (t >= 0.3) & (t < LEAVES_S)
    assert valid[in_view].mean() >= 0.8 and np.all(np.isfinite(kp[in_view & (valid > 0.5)]))
    # While it waves, the wrist moves side to side along X of U, 3 cm either way, as drawn.
    x = kp[waving & (valid > 0.5), 0]
    assert 0.03 < x.max() - x.min() < 0.09
    gone = t >= LEAVES_S + 0.1
    assert np.all(valid[gone] == 0) and np.all(np.isnan(kp[gone]))
    watchdogs = [e.time for e in log.events if e.kind == "watchdog"]
    assert not [w for w in watchdogs if 0.5 < w < WAVE_S]
    # The watchdog fires within one policy period of the first frame without the hand.
    assert [w for w in watchdogs if LEAVES_S <= w <= LEAVES_S + 0.15]
    # The thumbs-up paused once held 0.5 s; the second resumed.
    pauses = [e for e in log.events if e.kind == "pause"]
    resumes = [e for e in log.events if e.kind == "resume" and "source" in e.detail]
    assert len(pauses) == 1 and SIGN_S[0] + 0.5 <= pauses[0].time <= SIGN_S[0] + 0.75 and "source: hand sign" in pauses[0].detail
    assert len(resumes) == 1 and SIGN_S[1] + 0.5 <= resumes[0].time <= SIGN_S[1] + 0.75 and "source: hand sign" in resumes[0].detail
    paused = (log.command_time > pauses[0].time + 0.6) & (log.command_time < resumes[0].time)
    assert np.abs(log.command_twist[paused]).max() < 1e-9  # at rest while paused
    with h5py.File(log_path) as f:
        assert {"time", "valid", "keypoints"} <= set(f["gesture"])


def test_video_stream_ends_frozen(hand_video):
    from rtcohand_drake.vision.capture import HandPipeline, VideoFileTracker

    tracker = VideoFileTracker(hand_video, HandPipeline(CALIBRATION))
    try:
        assert tracker.fps == pytest.approx(30.0) and tracker.duration_s == pytest.approx(7.2)
        keypoints, t = tracker.latest(0.5)
        assert keypoints.shape == (21, 3) and t == pytest.approx(0.5)
        assert tracker.latest(6.5) == (None, pytest.approx(6.5))
        after = [tracker.latest(s) for s in (7.2, 7.3, 8.0)]
        assert all(k is None and ft == after[0][1] for k, ft in after)  # closed: the frame time stops
        assert tracker.latest(0.2)[0] is not None  # an earlier time rewinds the file
    finally:
        tracker.close()


def test_run_log_gesture_datasets_for_a_scripted_run(tmp_path):
    from rtcohand_drake.run import main
    from rtcohand_drake.run_log import read_run_log

    path = tmp_path / "scripted.h5"
    assert main(["--gesture-source", "scripted", "--duration", "0.5", "--no-meshcat", "--log", str(path)]) == 0
    log = read_run_log(path)
    assert len(log.gesture_time) == 6 and log.gesture_keypoints.shape == (6, 63)
    assert np.all(np.isnan(log.gesture_keypoints)) and set(np.unique(log.gesture_valid)) <= {0.0, 1.0}


@pytest.mark.parametrize("args, fragment", [
    (["--gesture-source", "camera"], "exactly one of --camera N and --video PATH"),
    (["--camera", "0", "--video", "x.avi"], "exactly one of"),
    (["--gesture-source", "synthetic", "--video", "x.avi"], "go with --gesture-source camera"),
])
def test_camera_flag_errors(args, fragment):
    from rtcohand_drake.run import main

    with pytest.raises(InputError, match=fragment):
        main(args + ["--no-meshcat"])


def test_missing_video_or_calibration_is_one_line(tmp_path, context_file):
    from rtcohand_drake.run import main

    common = ["--context-file", str(context_file), "--no-meshcat"]
    missing = tmp_path / "none.avi"
    with pytest.raises(InputError, match="no such video file") as err:
        main(["--video", str(missing), *common])
    assert str(missing) in str(err.value)
    with pytest.raises(InputError, match="no such camera calibration file") as err:
        main(["--video", str(missing), "--camera-calibration", str(tmp_path / "none.yaml"), *common])
    assert "none.yaml" in str(err.value)


def _stderr_of(*argv, timeout=180):
    done = subprocess.run([sys.executable, *argv], capture_output=True, text=True, timeout=timeout)
    return done.returncode, done.stderr


def test_bad_video_stderr_is_exactly_one_line(tmp_path):
    """A missing video file is one line, found before MediaPipe loads; a file that is no video closes
    the landmarker already started: no finaliser's traceback, no library log lines."""
    missing = tmp_path / "none.avi"
    for module, args in (("rtcohand_drake.run", ["--no-meshcat"]),
                         ("rtcohand_drake.record", ["--out", str(tmp_path / "me.h5"), "--user", "ME", "--no-meshcat"])):
        status, err = _stderr_of("-m", module, "--video", str(missing), *args)
        assert status == 2 and err.splitlines() == [f"{module}: error: {missing}: no such video file"], err
    junk = tmp_path / "junk.avi"
    junk.write_text("not a video\n")
    calibration = tmp_path / "cam.yaml"
    calibration.write_text("camera_position_m: [0, 0.6, 0]\n")
    status, err = _stderr_of("-m", "rtcohand_drake.run", "--video", str(junk), "--camera-calibration",
                             str(calibration), "--no-meshcat")
    assert status == 2 and err.splitlines() == [
        f"rtcohand_drake.run: error: {junk}: cannot open it as a video stream"], err


LANDMARKER_LEFT_OPEN = """
import sys
import numpy as np
from rtcohand_drake.vision.landmarker import HandLandmarker
lm = HandLandmarker(video=True, verbose=sys.argv[1] == "verbose")
lm.detect(np.full((240, 320, 3), 128, np.uint8), 0.1)
print("the program's own line", file=sys.stderr)
"""  # and exits without closing it


def test_library_lines_are_told_from_the_programs_own():
    from rtcohand_drake.vision.library_log import library_line

    theirs = [b"INFO: [environment.cc:36] Creating LiteRT environment with options\n",
              b"WARNING: Read-only tensor #3 (model_1/model/up_sampling2d_1/mul) has an unaligned buffer\n",
              b"INFO: Created TensorFlow Lite XNNPACK delegate for CPU.\n",
              b"WARNING: Logging before InitGoogle() is written to STDERR\n",
              b"W0000 00:00:1796554543.892350    3745 inference_runner_litert.cc:1433] Input tensor memory\n",
              b"I0000 00:00:1796554543.908870    3745 landmark_projection_calculator.cc:81] Using NORM_RECT\n"]
    ours = [b"warning: no --camera-calibration given: using the defaults\n", b"INFO:drake:Meshcat listening\n",
            b"rtcohand_drake.run: error: x.avi: no such video file\n", b"Traceback (most recent call last):\n",
            b"E0000 00:00:1796554543.9    3745 calculator_graph.cc:12] a MediaPipe error stays\n",
            b"\rreading u10's clips:  25%|###\n"]
    assert all(library_line(line) for line in theirs) and not any(library_line(line) for line in ours)


def test_landmarker_log_lines_only_with_verbose_and_closed_at_exit():
    status, err = _stderr_of("-c", LANDMARKER_LEFT_OPEN, "quiet", timeout=120)
    assert status == 0 and err.splitlines() == ["the program's own line"], err
    status, err = _stderr_of("-c", LANDMARKER_LEFT_OPEN, "verbose", timeout=120)
    assert status == 0 and "the program's own line" in err.splitlines()
    assert "INFO" in err and "Exception ignored" not in err and "Traceback" not in err


def test_live_tracker_thread_stamps_frames_and_freezes_at_the_end(tmp_path):
    """The live tracker on a file read as if it were a camera: frames stamped as read, then frozen."""
    import time

    from rtcohand_drake.vision.capture import HandPipeline, LiveCameraTracker

    frames = [f for f, _ in drawn_hand_frames(CALIBRATION, [("wave", 0.5)])]
    path = tmp_path / "live.avi"
    write_video(path, frames + [frames[-1]] * 15)  # then the same image again: a frozen camera
    started = time.monotonic()
    tracker = LiveCameraTracker(path, HandPipeline(CALIBRATION))
    try:
        first = tracker.latest(10.0)  # ties the tracker's clock to the diagram's time 10 s
        tied = time.monotonic()
        deadline = time.monotonic() + 30.0
        seen, shapes = [], set()
        while not tracker.closed and time.monotonic() < deadline:
            keypoints, t = tracker.latest(10.0)
            if keypoints is not None:
                shapes.add(keypoints.shape)
                if not seen or t != seen[-1]:
                    seen.append(t)
            time.sleep(0.005)
        ended = time.monotonic()
        assert tracker.closed
        # A frame is stamped when it is read: after the tracker started, before the loop ended,
        # on the diagram's clock (10 s when it was tied, advancing with the wall clock).
        earliest, latest = 10.0 - (tied - started), 10.0 + (ended - started)
        assert len(seen) >= 3 and seen == sorted(seen), seen
        assert all(earliest <= t <= latest for t in seen), (earliest, seen, latest)
        assert shapes == {(21, 3)}
        keypoints, t_end = tracker.latest(10.0)
        assert keypoints is None and t_end == tracker.latest(11.0)[1]  # closed: no new frame time
        assert t_end >= seen[-1]  # the last distinct frame, with a hand in it or not
        # The repeated images were not new frames: the last stamp is that of the last distinct one.
        assert len(tracker._pipeline.processing_s) == len(frames)
    finally:
        tracker.close()
    # At the first call either nothing had been read yet (no time at all) or a frame had, read
    # after the tracker started and before that call.
    first_keypoints, first_t = first
    if first_t == -math.inf:
        assert first_keypoints is None
    else:
        assert earliest <= first_t <= 10.0
        assert first_keypoints is None or first_keypoints.shape == (21, 3)


def test_bad_model_file_is_one_line(tmp_path):
    bad = tmp_path / "bad.task"
    bad.write_text("not a model bundle\n")
    with pytest.raises(InputError, match="not a usable hand landmarker bundle") as err:
        HandLandmarker(model=bad)
    assert str(bad) in str(err.value) and "\n" not in str(err.value)
    with pytest.raises(InputError, match="no hand landmarker model file"):
        HandLandmarker(model=tmp_path / "none.task")
