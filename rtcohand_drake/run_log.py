"""The run log (docs/interfaces.md, the run log): what a run commanded and what the robot did, as HDF5.

`RunLog` collects arrays and events during or after a run; `write_run_log`
writes them atomically (a temporary file in the same directory, then a
rename), so a crash never leaves a half-written log under the requested name.
`read_run_log` reads one back (tests, notebooks, plots).

Layout (docs/interfaces.md (the run log); extensions are marked +):
  /policy/time (P,) /policy/mean (P,6) /policy/std (P,6) + /policy/read_variance (P,)
  /command/time (M,) /command/twist (M,6) + /command/speed_scale (M,)
  /robot/time (K,) /robot/q (K,7) /robot/v (K,7) /robot/workpiece_pose (K,7)
  + /gesture/time (G,) + /gesture/valid (G,) + /gesture/frame_time (G,) + /gesture/keypoints (G,63)
  + /gesture/intended (G,6) (a simulated or recorded person's intended twist; (0, 6) for other sources)
  /events  compound (time f8, kind str, detail str)
  / attrs: scenario, model, gesture_source, completed, faces_inspected,
           completion_time, + format = "rtcohand-runlog", + version = 1
"""

from __future__ import annotations

import dataclasses as dc
import os
import tempfile
from pathlib import Path

import h5py
import numpy as np

from rtcohand_drake.data.dataset import give_usual_mode
from rtcohand_drake.errors import InputError

RUNLOG_FORMAT = "rtcohand-runlog"
RUNLOG_VERSION = 1


@dc.dataclass
class Event:
    time: float
    kind: str
    detail: str = ""


@dc.dataclass
class RunLog:
    scenario: str = ""
    model: str = ""
    gesture_source: str = ""
    completed: bool = False
    faces_inspected: int = 0
    completion_time: float = float("nan")
    policy_time: np.ndarray = dc.field(default_factory=lambda: np.zeros(0))
    policy_mean: np.ndarray = dc.field(default_factory=lambda: np.zeros((0, 6)))
    policy_std: np.ndarray = dc.field(default_factory=lambda: np.zeros((0, 6)))
    policy_read_variance: np.ndarray = dc.field(default_factory=lambda: np.zeros(0))
    command_time: np.ndarray = dc.field(default_factory=lambda: np.zeros(0))
    command_twist: np.ndarray = dc.field(default_factory=lambda: np.zeros((0, 6)))
    command_speed_scale: np.ndarray = dc.field(default_factory=lambda: np.zeros(0))
    robot_time: np.ndarray = dc.field(default_factory=lambda: np.zeros(0))
    robot_q: np.ndarray = dc.field(default_factory=lambda: np.zeros((0, 7)))
    robot_v: np.ndarray = dc.field(default_factory=lambda: np.zeros((0, 7)))
    robot_workpiece_pose: np.ndarray = dc.field(default_factory=lambda: np.zeros((0, 7)))
    # The gesture source's output at the policy rate: sample times (s), valid (0/1), the time of
    # the frame the gesture came from (s), the 21-point skeleton in U (m, NaN when the hand is lost).
    gesture_time: np.ndarray = dc.field(default_factory=lambda: np.zeros(0))
    gesture_valid: np.ndarray = dc.field(default_factory=lambda: np.zeros(0))
    gesture_frame_time: np.ndarray = dc.field(default_factory=lambda: np.zeros(0))
    gesture_keypoints: np.ndarray = dc.field(default_factory=lambda: np.zeros((0, 63)))
    # The twist a simulated or recorded person means at each of those samples (m/s, rad/s, U; a
    # recorded person's: the label of the frame played); empty for a source without one.
    gesture_intended: np.ndarray = dc.field(default_factory=lambda: np.zeros((0, 6)))
    events: list[Event] = dc.field(default_factory=list)
    extra_attrs: dict = dc.field(default_factory=dict)

    def add_event(self, time: float, kind: str, detail: str = "") -> None:
        self.events.append(Event(float(time), kind, detail))


_DATASETS = {
    "policy/time": "policy_time", "policy/mean": "policy_mean", "policy/std": "policy_std",
    "policy/read_variance": "policy_read_variance",
    "command/time": "command_time", "command/twist": "command_twist", "command/speed_scale": "command_speed_scale",
    "robot/time": "robot_time", "robot/q": "robot_q", "robot/v": "robot_v",
    "robot/workpiece_pose": "robot_workpiece_pose",
    "gesture/time": "gesture_time", "gesture/valid": "gesture_valid",
    "gesture/frame_time": "gesture_frame_time", "gesture/keypoints": "gesture_keypoints",
    "gesture/intended": "gesture_intended",
}
_EVENT_DTYPE = np.dtype([("time", "f8"), ("kind", h5py.string_dtype()), ("detail", h5py.string_dtype())])


def write_run_log(path: str | Path, log: RunLog) -> Path:
    """Writes `log` to `path` atomically; returns the path."""
    path = Path(path)
    directory = path.parent if str(path.parent) else Path(".")
    if not directory.is_dir():
        raise InputError(f"{path}: cannot write the run log: directory {directory} does not exist")
    fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".partial", dir=directory)
    os.close(fd)
    try:
        with h5py.File(tmp, "w") as f:
            f.attrs["format"] = RUNLOG_FORMAT
            f.attrs["version"] = RUNLOG_VERSION
            for key in ("scenario", "model", "gesture_source"):
                f.attrs[key] = getattr(log, key)
            f.attrs["completed"] = bool(log.completed)
            f.attrs["faces_inspected"] = int(log.faces_inspected)
            f.attrs["completion_time"] = float(log.completion_time)
            for key, value in log.extra_attrs.items():
                f.attrs[key] = value
            for name, field in _DATASETS.items():
                f.create_dataset(name, data=np.asarray(getattr(log, field), dtype=np.float64))
            events = np.array([(e.time, e.kind, e.detail) for e in log.events], dtype=_EVENT_DTYPE)
            f.create_dataset("events", data=events, dtype=_EVENT_DTYPE)
        give_usual_mode(tmp)
        os.replace(tmp, path)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise
    return path


def _plain(value):
    """An HDF5 attribute as a plain Python value."""
    if isinstance(value, bytes):
        return value.decode()
    if isinstance(value, np.generic):
        return value.item()
    return value


def read_run_log(path: str | Path) -> RunLog:
    path = Path(path)
    try:
        with h5py.File(path, "r") as f:
            log = RunLog(
                scenario=str(f.attrs.get("scenario", "")), model=str(f.attrs.get("model", "")),
                gesture_source=str(f.attrs.get("gesture_source", "")),
                completed=bool(f.attrs.get("completed", False)),
                faces_inspected=int(f.attrs.get("faces_inspected", 0)),
                completion_time=float(f.attrs.get("completion_time", np.nan)))
            known = {"format", "version", "scenario", "model", "gesture_source", "completed",
                     "faces_inspected", "completion_time"}
            log.extra_attrs = {k: _plain(v) for k, v in f.attrs.items() if k not in known}
            for name, field in _DATASETS.items():
                if name in f:
                    setattr(log, field, f[name][()])
            if "events" in f:
                for row in f["events"][()]:
                    kind, detail = (x.decode() if isinstance(x, bytes) else str(x) for x in (row["kind"], row["detail"]))
                    log.events.append(Event(float(row["time"]), kind, detail))
    except (OSError, KeyError) as err:
        raise InputError(f"{path}: not a readable run log: {err}") from None
    return log
