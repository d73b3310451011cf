"""`python -m rtcohand_drake.run`: build the diagram for a scenario, simulate it, log it.

    python -m rtcohand_drake.run [--scenario NAME | PATH.yaml]   # default: the built-in inspection
        [--duration S] [--realtime-rate R] [--no-meshcat] [--no-wait] [--seed N]
        [--gesture-source synthetic|replay|recorded|camera|scripted|joystick]
        [--gesture-file PATH.h5 [--clip USER/CLIP | --clip USER] [--split test]]   # recorded: --clip PERSON
        [--camera N | --video PATH] [--camera-calibration FILE]   # with --gesture-source camera
        [--context-file PATH.h5 [PATH.h5 ...] [--context-user USER]] [--user ID [--population-seed N]]
        [--model PATH.pt] [--log PATH.h5] [--html PATH.html] [--filter-mode paper|responsive]
        [--hardware --robot-ip IP [--dry-run]]                  # the real arm (kortex_station)
        [--verbose]                                             # the libraries' own log lines too

Prints the Meshcat URL (unless --no-meshcat), then a summary: faces
inspected, completion time, peak workpiece speeds and safety events; for a
replay of labelled clips also how well the policy read them
(`analysis.replay_read`). Without
--duration the run ends `done_hold_s` (3 s) after all six faces are inspected,
or at the scenario's `duration_s` (180 s), or when a replayed stream ends.
With Meshcat the page then keeps serving, replaying the recorded run, until
Ctrl-C (--no-wait: exit at once). Bad input
exits with status 2 and one line on stderr naming the file and the problem.
"""

from __future__ import annotations

import argparse
import logging
import math
import sys
import time
from pathlib import Path
from typing import Sequence

import numpy as np

from rtcohand_drake.errors import ArgumentParser, InputError, non_negative_int, run_cli, writable_file_path


def make_parser() -> argparse.ArgumentParser:
    p = ArgumentParser(prog="python -m rtcohand_drake.run", description=__doc__.split("\n")[0])
    p.add_argument("--scenario", default="inspection", help="built-in scenario name or path to a YAML file")
    p.add_argument("--duration", type=float, default=None,
                   help="simulated seconds (default: the scenario's, or the end of a replayed stream)")
    p.add_argument("--realtime-rate", type=float, default=None,
                   help="target real-time rate; 0 = as fast as possible (default 1 with Meshcat, 0 without)")
    p.add_argument("--no-meshcat", action="store_true", help="run headless")
    p.add_argument("--no-wait", action="store_true",
                   help="with Meshcat: exit at the end of the run instead of serving the page until Ctrl-C")
    p.add_argument("--seed", type=non_negative_int, default=0,
                   help="seeds the policy's latent draws and the simulated person")
    from rtcohand_drake.systems.gestures.registry import GESTURE_SOURCES

    p.add_argument("--gesture-source", choices=tuple(GESTURE_SOURCES), default=None,
                   help="; ".join(f"{name}: {entry.summary}" for name, entry in GESTURE_SOURCES.items())
                   + " (default: replay with --gesture-file, else synthetic)")
    p.add_argument("--gesture-file", type=Path, default=None, help="dataset file to replay (docs/interfaces.md, the gesture dataset file)")
    p.add_argument("--clip", default=None, help="USER/CLIP (one clip) or USER (all that user's clips, in name order); "
                   "with --gesture-source recorded: the person")
    p.add_argument("--split", choices=("train", "test"), default=None,
                   help="replay source: only the clips of this split (test: the person's held-out clips, "
                        "their other labelled clips the context)")
    p.add_argument("--camera", type=non_negative_int, default=None, help="camera source: the OpenCV camera number")
    p.add_argument("--video", type=Path, default=None,
                   help="camera source: a video file, played in simulated time at its own frame rate")
    p.add_argument("--camera-calibration", type=Path, default=None,
                   help="camera source: intrinsics and the camera's pose in the user frame (YAML; "
                        "default: a webcam facing the person, with a warning)")
    p.add_argument("--context-file", type=Path, nargs="+", action="extend", default=None, metavar="PATH.h5",
                   help="a user's own labelled clips as context; several files are read together as one "
                        "context (say a first session and one re-recording weak motions)")
    p.add_argument("--context-user", default=None,
                   help="which user of --context-file (needed when the files hold more than one)")
    p.add_argument("--user", default=None, help="the simulated person's user id (synthetic source)")
    p.add_argument("--population-seed", type=non_negative_int, default=None,
                   help="the generated population the simulated person comes from (data.generate --seed; "
                        "default 0, the benchmark's)")
    p.add_argument("--model", type=Path, default=None, help="exported TorchScript policy (default: the scenario's)")
    p.add_argument("--filter-mode", choices=("paper", "responsive"), default=None,
                   help="override the scenario's command_filter.mode")
    p.add_argument("--log", type=Path, default=None, help="write the run log (HDF5, docs/interfaces.md (the run log))")
    p.add_argument("--html", type=Path, default=None,
                   help="save the Meshcat animation as a standalone HTML file (default: beside --log)")
    p.add_argument("--hardware", action="store_true", help="drive the real arm (Kortex API) instead of the simulation")
    p.add_argument("--robot-ip", default=None, help="the arm's address (with --hardware)")
    p.add_argument("--dry-run", action="store_true", help="with --hardware: connect and show the arm, send no motion")
    p.add_argument("--verbose", action="store_true",
                   help="show the libraries' own INFO lines on stderr (hidden by default): Drake's, and with "
                        "the camera source MediaPipe's and LiteRT's INFO and WARNING lines")
    return p


def _check_args(args) -> None:
    if args.duration is not None and not (math.isfinite(args.duration) and args.duration > 0):
        raise InputError(f"command line: --duration must be a positive number of seconds, got {args.duration}")
    if args.realtime_rate is not None and not (math.isfinite(args.realtime_rate) and args.realtime_rate >= 0):
        raise InputError(f"command line: --realtime-rate must be >= 0, got {args.realtime_rate}")
    for flag, path in (("--log", args.log), ("--html", args.html)):
        if path is not None:
            writable_file_path(path, flag)
    camera_flags = args.camera is not None or args.video is not None or args.camera_calibration is not None
    if args.gesture_source is None:
        args.gesture_source = ("replay" if args.gesture_file is not None else "camera" if camera_flags
                               else "synthetic")
    if args.gesture_source == "replay" and args.gesture_file is None:
        raise InputError("command line: --gesture-source replay needs --gesture-file PATH.h5")
    if args.gesture_source == "recorded" and (args.gesture_file is None or args.clip is None):
        raise InputError("command line: --gesture-source recorded needs --gesture-file PEOPLE.h5 --clip PERSON")
    if args.gesture_source not in ("replay", "recorded") and (args.gesture_file is not None or args.clip is not None):
        raise InputError("command line: --gesture-file and --clip go with --gesture-source replay or recorded")
    if args.split is not None and args.gesture_source != "replay":
        raise InputError("command line: --split goes with --gesture-source replay")
    if args.gesture_source == "camera" and (args.camera is None) == (args.video is None):
        raise InputError("command line: --gesture-source camera needs exactly one of --camera N and --video PATH")
    if args.gesture_source != "camera" and camera_flags:
        raise InputError("command line: --camera, --video and --camera-calibration go with --gesture-source camera")
    from rtcohand_drake.systems.gestures.registry import GESTURE_SOURCES

    if not GESTURE_SOURCES[args.gesture_source].uses_policy and (args.model is not None or args.context_file):
        raise InputError(f"command line: --model and --context-file go with a source the policy reads; "
                         f"--gesture-source {args.gesture_source} commands the arm without it")
    if args.population_seed is not None and args.gesture_source not in ("synthetic", "joystick"):
        raise InputError("command line: --population-seed goes with the synthetic and joystick gesture sources")
    if args.context_user is not None and args.context_file is None:
        raise InputError("command line: --context-user goes with --context-file")
    if args.hardware and not args.robot_ip:
        raise InputError("command line: --hardware needs --robot-ip IP (the arm's address)")
    if not args.hardware and (args.robot_ip is not None or args.dry_run):
        raise InputError("command line: --robot-ip and --dry-run go with --hardware")


def _resolve_model(args, scenario) -> Path:
    """--model, else the scenario's policy file for the source's hands (a real hand's, or `policy.model`)."""
    from rtcohand_drake.cell.robot_files import policy_file_path
    from rtcohand_drake.systems.gestures.registry import policy_model_name, reads_real_hands

    if args.model is not None:
        return args.model
    real = reads_real_hands(args.gesture_source, getattr(args, "gesture_file", None))
    return policy_file_path(policy_model_name(scenario.policy, real))


def _build(args, scenario, meshcat, station=None):
    from rtcohand_drake.diagram import build_run_diagram
    from rtcohand_drake.systems.gestures.registry import GESTURE_SOURCES, make_gesture_source

    if not GESTURE_SOURCES[args.gesture_source].uses_policy:
        setup = make_gesture_source(args.gesture_source, args, scenario)
        return build_run_diagram(scenario, source=setup.source, meshcat=meshcat, station=station,
                                 gesture_source=args.gesture_source), setup.end_time
    from rtcohand_drake.learning.policy_file import load_policy

    model_path = _resolve_model(args, scenario)
    model = load_policy(model_path)  # a bad model file fails before anything else is built
    model.source_path = str(model_path)
    setup = make_gesture_source(args.gesture_source, args, scenario)
    try:
        return _build_with_policy(args, scenario, meshcat, station, model, setup)
    except BaseException:
        if hasattr(setup.source, "close"):
            setup.source.close()  # a camera source releases its camera and tracker on every path
        raise


def _policy_context(model, load, real_hands: bool = False):
    """(pieces, user) from `load(path_shape)` for the policy file `model`. A file that reads the hand's path
    and shape gets them, unless its fast-turn gate reads this person with the CCHP alone: the 36 features
    then give the same read, and the path and shape are not built (about 0.3-0.8 s of start-up). Clips of
    a real hand (`real_hands`), whose palm turns fast, are loaded with them at once, so that they are not
    read twice (the gate still decides, from the full features)."""
    from rtcohand_drake.data.hand_features import FEATURE_DIM
    from rtcohand_drake.data.sampling import pack_context
    from rtcohand_drake.learning.path_shape_policy import turned_away_by_fast_turns

    if int(model.feature_dim) <= FEATURE_DIM:
        return load(False)
    if real_hands:
        return load(True)
    pieces, user = load(False)
    if pieces:
        x_c, _, mask = pack_context(pieces)
        if turned_away_by_fast_turns(model, x_c, mask):
            return pieces, user
    return load(True)


def _build_with_policy(args, scenario, meshcat, station, model, setup):
    from rtcohand_drake.data.dataset import (context_pieces, is_generated, label_lag_s, lost_hand_share,
                                             missing_motions)
    from rtcohand_drake.diagram import build_run_diagram
    from rtcohand_drake.systems.gestures.registry import reads_real_hands
    from rtcohand_drake.systems.policy import CchpPolicy

    rate = scenario.policy.rate_hz
    user, lag = None, 0.0
    real_hands = reads_real_hands(args.gesture_source, getattr(args, "gesture_file", None))
    if args.context_file is not None:
        pieces, user = _policy_context(
            model, lambda wide: context_pieces(args.context_file, args.context_user, rate, path_shape=wide),
            real_hands=not all(is_generated(path) for path in args.context_file))
        lag = label_lag_s(args.context_file)
    elif setup.default_context is not None:
        pieces, _ = _policy_context(model, lambda wide: (setup.default_context(path_shape=wide), None),
                                    real_hands=real_hands)
    else:
        raise InputError(f"command line: --gesture-source {args.gesture_source} needs --context-file "
                         "(the user's own labelled clips)")
    lost = lost_hand_share(pieces)
    if lost > 0.5:
        print(f"warning: the context's clips lose the hand in {lost:.0%} of their labelled steps, which the "
              "policy reads as no motion: it learns little from them; record them again with the hand in view",
              file=sys.stderr)
    missing = missing_motions(pieces)
    if missing:
        record = f"python -m rtcohand_drake.record --only {','.join(missing)}"
        if user is not None:  # into a file of their own, given after the others
            record = (f"python -m rtcohand_drake.record --out MORE.h5 --user {user} --only {','.join(missing)}, "
                      "then add MORE.h5 to --context-file")
        print(f"warning: the context holds no example of {', '.join(missing)}, so gestures for them may be "
              f"read wrongly; record them: {record}", file=sys.stderr)
    policy = CchpPolicy.from_scenario(model, pieces, scenario.policy, seed=args.seed, label_lag_s=lag)
    from rtcohand_drake.learning.rest_release import release_advice

    advice = release_advice(policy.release) if scenario.policy.rest_release else None
    if advice is not None and real_hands:
        print(f"warning: {advice}", file=sys.stderr)
    return build_run_diagram(scenario, source=setup.source, policy=policy, meshcat=meshcat, station=station,
                             gesture_source=args.gesture_source), setup.end_time


def main(argv: Sequence[str] | None = None) -> int:
    args = make_parser().parse_args(argv)
    _check_args(args)
    from rtcohand_drake.scenario import load_scenario

    scenario = load_scenario(args.scenario)
    if args.filter_mode is not None:
        scenario.command_filter.mode = args.filter_mode

    # Imports that load pydrake, torch and the models come after the argument checks.
    from pydrake.systems.analysis import Simulator

    if not args.verbose:  # Drake's INFO lines (contexts allocated; Meshcat's address, printed below)
        logging.getLogger("drake").setLevel(logging.WARNING)

    from rtcohand_drake.diagram import collect_run_log, peak_speeds
    from rtcohand_drake.analysis.inspection import score_run_log
    from rtcohand_drake.run_log import write_run_log
    from rtcohand_drake.systems.inspection_monitor import until_done

    meshcat = None
    if not args.no_meshcat:
        from pydrake.geometry import Meshcat, MeshcatParams

        meshcat = Meshcat(MeshcatParams(host="localhost", port=0))
        print(f"Meshcat: {meshcat.web_url()}", flush=True)
    station = None
    if args.hardware:  # the session stops the arm at exit even if a step below fails (kortex_station)
        from rtcohand_drake.stations.kortex import make_kortex_station

        station = make_kortex_station(scenario, args.robot_ip, dry_run=args.dry_run)
    try:
        run, end_time = _build(args, scenario, meshcat, station)
    except BaseException:
        if station is not None:
            station.close()
        raise
    duration = args.duration if args.duration is not None else (end_time or scenario.duration_s)
    # With no --duration and no stream end, the run ends a short hold after the task is done.
    stop_when_done = args.duration is None and end_time is None and scenario.stop_when_done
    rate = args.realtime_rate if args.realtime_rate is not None else (1.0 if meshcat or station is not None else 0.0)

    simulator = Simulator(run.diagram)
    simulator.set_target_realtime_rate(rate)
    if run.visualizer is not None:
        run.visualizer.StartRecording(set_transforms_while_recording=True)
    if stop_when_done:
        simulator.set_monitor(until_done(run.monitor, scenario.done_hold_s))
    simulator.Initialize()
    wall_start = time.perf_counter()
    interrupted = False
    fault = None
    try:
        simulator.AdvanceTo(duration)
    except KeyboardInterrupt:
        interrupted = True
        print("interrupted: stopping the run and writing what was recorded", file=sys.stderr)
    except InputError as err:  # a hardware fault: the arm is stopped below, the log written, then exit 2
        fault = err
    finally:
        if station is not None:
            station.close()  # Stop(), then close the session, on every exit path
        if hasattr(run.source, "close"):
            run.source.close()  # a camera source releases its camera and tracker
    wall = time.perf_counter() - wall_start
    root = simulator.get_context()
    sim_time = root.get_time()

    log = collect_run_log(run, root, scenario)
    if station is not None:
        log.events = sorted(log.events + station.events, key=lambda e: e.time)
    clearance, clearance_t = score_run_log(log, scenario)
    log.extra_attrs.update(seed=args.seed, sim_duration_s=sim_time, interrupted=interrupted,
                           filter_mode=scenario.command_filter.mode)
    if fault is not None:
        log.add_event(sim_time, "fault", str(fault))
        log.completed = False
    if args.log is not None:
        write_run_log(args.log, log)
    if fault is not None:
        raise fault
    html = args.html or (args.log.with_suffix(".html") if args.log is not None else None)
    if run.visualizer is not None:
        run.visualizer.StopRecording()
        run.visualizer.PublishRecording()
        if html is not None:
            html.write_text(meshcat.StaticHtml())

    v_peak, w_peak = peak_speeds(log.robot_time, log.robot_workpiece_pose)
    completion = f"{log.completion_time:.1f} s" if log.completed else "not completed"
    policy = f", policy {Path(log.model).name}" if log.model else ""  # which file read the hand
    print(f"scenario {scenario.name}, gesture source {run.gesture_source}{policy}: {sim_time:.1f} s simulated "
          f"in {wall:.2f} s ({sim_time / max(wall, 1e-9):.1f}x real time)")
    print(f"faces inspected: {log.faces_inspected}/6, completion: {completion}")
    print(f"peak workpiece speed: {v_peak:.3f} m/s, {w_peak:.3f} rad/s")
    near = "never near the mold" if not np.isfinite(clearance) else (
        f"TOUCHED the mold at {clearance_t:.1f} s" if clearance <= 0.0 else
        f"cleared the mold walls (closest {clearance * 1e3:.1f} mm)")
    print(f"mold: {near}")
    cell = float(log.extra_attrs.get("cell_min_clearance_m", np.inf))
    contact = next((e for e in log.events if e.kind == "cell_contact"), None)
    print("cell (arm, gripper, part vs table, mold, glass): " + (
        f"TOUCHED at {contact.time:.1f} s: {contact.detail}" if contact is not None else
        f"clear (closest {cell * 1e3:.1f} mm)" if np.isfinite(cell) else "never within 10 cm"))
    kinds: dict[str, int] = {}
    for e in log.events:
        kinds[e.kind] = kinds.get(e.kind, 0) + 1
    print("events: " + (", ".join(f"{k} x{n}" for k, n in sorted(kinds.items())) or "none"))
    if run.gesture_source == "replay":
        from rtcohand_drake.analysis.replay_read import log_read

        read = log_read(log)
        if read is not None and read.zero > 0:
            print(f"read of the replayed labels (the policy's output, back to back): {read.line()}")
    if args.log is not None:
        print(f"run log: {args.log}")
    if html is not None and run.visualizer is not None:
        print(f"animation: {html}")
    if meshcat is not None and not args.no_wait and not interrupted:
        print(f"Meshcat keeps serving at {meshcat.web_url()}: the page replays the recorded run "
              "(the animation controls). Ctrl-C to quit.", flush=True)
        try:
            while True:
                time.sleep(1.0)
        except KeyboardInterrupt:
            pass
    return 130 if interrupted else 0


def entry_point() -> None:
    sys.exit(run_cli(main, prog="rtcohand_drake.run"))


if __name__ == "__main__":
    entry_point()
