"""A fake Kinova Gen3 behind the Kortex API: a stand-in for the physical arm for tests.

`FakeKortexArm` is an in-process arm that answers the part of the `kortex_api`
call surface the hardware station uses (`rtcohand_drake.stations.kortex`):

    api = FakeKortexArm(q0_rad).api()       # what `import kortex_api...` would give
    transport = api.TCPTransport(); router = api.RouterClient(transport, on_error)
    transport.connect(ip, 10000); api.SessionManager(router).CreateSession(info)
    base = api.BaseClient(router); base.SetServoingMode(...); base.SendJointSpeedsCommand(...)
    api.BaseCyclicClient(router).RefreshFeedback().actuators[i].position   # degrees, 0..360
    base.Stop(); session.CloseSession(); transport.disconnect()

The arm integrates the commanded joint speeds (deg/s) ideally: a speed holds
until the next command or `Stop()`, as on the real arm, which has no velocity
watchdog. Time comes from an injected clock (for tests, the Drake simulator's
time, so a run is deterministic; by default `time.monotonic`). Feedback
reports positions wrapped to [0, 360) degrees, velocities in deg/s.

Every call is recorded (`calls`) with the arm's clock, the wall clock, the
calling thread and its outcome, whether it succeeded or raised.

Fault switches
  timeout_next(n)    the next n calls raise `FakeTimeoutError` (a call that timed out)
  drop_connection()  every later call raises `FakeConnectionError`; the router's
                     error callback is told once
  freeze(timeout_s)  the control loop's periodic calls (`RefreshFeedback`,
                     `SendJointSpeedsCommand`) block, as if the client hung inside a
                     network call, until `unfreeze()`, or raise `FakeTimeoutError`
                     after `timeout_s`. The arm meanwhile keeps executing the last
                     speed command. `Stop()` and the teardown calls still go through:
                     the freeze models a stalled client, the case the client's own
                     watchdog (on another thread) exists for.
The server-side checks a real arm makes are mimicked where a client bug would
show: commands need an open session and single-level servoing, speeds above the
actuators' hard limits and unknown joint identifiers are refused.
"""

from __future__ import annotations

import dataclasses as dc
import threading
import time
from types import SimpleNamespace
from typing import Callable, Sequence

import numpy as np

N_JOINTS = 7
# Actuator hard speed limits (deg/s): large actuators 1-4, small 5-7 (reference/facts.md).
HARD_SPEED_LIMITS_DEG_S = np.array([80.0] * 4 + [70.0] * 3)
# Servoing modes, numbered as in the maker's Base protocol.
SINGLE_LEVEL_SERVOING = 2
LOW_LEVEL_SERVOING = 3
# Calls the control loop makes every period; `freeze()` blocks these.
PERIODIC_CALLS = frozenset({"RefreshFeedback", "SendJointSpeedsCommand"})


class FakeKortexError(Exception):
    """Base of the fake's errors (the real API raises KClientException / KServerException)."""


class FakeTimeoutError(FakeKortexError):
    pass


class FakeConnectionError(FakeKortexError):
    pass


class FakeServerError(FakeKortexError):
    """The arm refused a request (what the real arm reports as a server error)."""


# --- message classes: the protobuf fields the station reads and writes --------------------


class _Message:
    """Fixed fields like a protobuf message: assigning an unknown field raises AttributeError."""

    __slots__ = ()

    def __init__(self, **fields):
        for name in self.__slots__:
            object.__setattr__(self, name, self._default(name))
        for name, value in fields.items():
            setattr(self, name, value)

    def _default(self, name):
        return 0

    def __repr__(self):
        return f"{type(self).__name__}({', '.join(f'{n}={getattr(self, n)!r}' for n in self.__slots__)})"


class JointSpeed(_Message):
    __slots__ = ("joint_identifier", "value", "duration")


class _Repeated(list):
    def __init__(self, item_type):
        super().__init__()
        self._item_type = item_type

    def add(self, **fields):
        item = self._item_type(**fields)
        self.append(item)
        return item


class JointSpeeds(_Message):
    __slots__ = ("joint_speeds", "duration")

    def _default(self, name):
        return _Repeated(JointSpeed) if name == "joint_speeds" else 0


class ServoingModeInformation(_Message):
    __slots__ = ("servoing_mode",)


class CreateSessionInfo(_Message):
    __slots__ = ("username", "password", "session_inactivity_timeout", "connection_inactivity_timeout")

    def _default(self, name):
        return "" if name in ("username", "password") else 0


class ActuatorFeedback(_Message):
    __slots__ = ("position", "velocity", "torque")


class BaseFeedback(_Message):
    __slots__ = ("tool_pose_x", "tool_pose_y", "tool_pose_z",
                 "tool_pose_theta_x", "tool_pose_theta_y", "tool_pose_theta_z")


class Feedback(_Message):
    __slots__ = ("actuators", "base")

    def _default(self, name):
        return [ActuatorFeedback() for _ in range(N_JOINTS)] if name == "actuators" else BaseFeedback()


# --- the arm ---------------------------------------------------------------------------------


@dc.dataclass
class Call:
    time: float      # the arm's clock (s)
    wall: float      # time.monotonic() (s)
    target: str      # transport | router | session | base | base_cyclic
    name: str
    args: tuple
    thread: str
    outcome: str = "pending"  # "ok", or the error it raised


class FakeKortexArm:
    """A simulated Gen3 answering Kortex API calls (see the module docstring)."""

    def __init__(self, q0_rad: Sequence[float] = (0.0,) * N_JOINTS, clock: Callable[[], float] | None = None,
                 credentials: tuple[str, str] = ("admin", "admin"), robot_ip: str | None = None):
        self.clock = clock or time.monotonic
        self.credentials = tuple(credentials)
        self.robot_ip = robot_ip  # when set, connecting to any other address fails
        self._positions_deg = np.degrees(np.asarray(q0_rad, dtype=float)).copy()  # unwrapped
        self._speeds_deg_s = np.zeros(N_JOINTS)
        self._t_last: float | None = None
        self._lock = threading.RLock()
        self.calls: list[Call] = []
        self.connected = False
        self.session_open = False
        self.servoing_mode = 0
        self._error_callbacks: list[Callable] = []
        self._timeouts_left = 0
        self._dropped = False
        self._unfrozen = threading.Event()
        self._unfrozen.set()
        self._freeze_timeout_s: float | None = None

    # -- what the station imports -------------------------------------------------------------

    def api(self) -> SimpleNamespace:
        """The fake counterpart of the kortex_api modules the station uses."""
        arm = self

        class TCPTransport:
            def connect(self, ip, port):
                arm._enter("transport", "connect", (ip, port), lambda: arm._connect(ip, port))

            def disconnect(self):
                arm._enter("transport", "disconnect", (), arm._disconnect)

        class RouterClient:
            def __init__(self, transport, error_callback=None):
                if error_callback is not None:
                    arm._error_callbacks.append(error_callback)

        class SessionManager:
            def __init__(self, router):
                pass

            def CreateSession(self, info):
                arm._enter("session", "CreateSession", (info,), lambda: arm._create_session(info))

            def CloseSession(self, *options):
                arm._enter("session", "CloseSession", options, arm._close_session)

        class BaseClient:
            def __init__(self, router):
                pass

            def SetServoingMode(self, mode):
                arm._enter("base", "SetServoingMode", (mode,), lambda: arm._set_servoing_mode(mode))

            def SendJointSpeedsCommand(self, command):
                arm._enter("base", "SendJointSpeedsCommand", (command,), lambda: arm._joint_speeds(command))

            def Stop(self):
                arm._enter("base", "Stop", (), arm._stop)

        class BaseCyclicClient:
            def __init__(self, router):
                pass

            def RefreshFeedback(self):
                return arm._enter("base_cyclic", "RefreshFeedback", (), arm._feedback)

        base_pb2 = SimpleNamespace(JointSpeeds=JointSpeeds, ServoingModeInformation=ServoingModeInformation,
                                   SINGLE_LEVEL_SERVOING=SINGLE_LEVEL_SERVOING, LOW_LEVEL_SERVOING=LOW_LEVEL_SERVOING)
        return SimpleNamespace(TCPTransport=TCPTransport, RouterClient=RouterClient, SessionManager=SessionManager,
                               BaseClient=BaseClient, BaseCyclicClient=BaseCyclicClient, Base_pb2=base_pb2,
                               Session_pb2=SimpleNamespace(CreateSessionInfo=CreateSessionInfo))

    # -- fault switches -----------------------------------------------------------------------

    def timeout_next(self, n: int = 1) -> None:
        with self._lock:
            self._timeouts_left = int(n)

    def drop_connection(self) -> None:
        with self._lock:
            self._dropped = True
            callbacks = list(self._error_callbacks)
        for callback in callbacks:
            callback(FakeConnectionError("connection to the arm lost"))

    def freeze(self, timeout_s: float | None = None) -> None:
        with self._lock:
            self._freeze_timeout_s = timeout_s
            self._unfrozen.clear()

    def unfreeze(self) -> None:
        self._unfrozen.set()

    # -- what tests read ----------------------------------------------------------------------

    def joint_positions_rad(self) -> np.ndarray:
        """The arm's true (unwrapped) joint angles now."""
        with self._lock:
            self._advance()
            return np.radians(self._positions_deg)

    def joint_speeds_deg_s(self) -> np.ndarray:
        with self._lock:
            return self._speeds_deg_s.copy()

    def calls_to(self, *targets: str) -> list[Call]:
        with self._lock:
            return [c for c in self.calls if not targets or c.target in targets]

    def call_names(self, *targets: str) -> list[str]:
        return [c.name for c in self.calls_to(*targets)]

    # -- internals ----------------------------------------------------------------------------

    def _advance(self) -> None:
        now = self.clock()
        if self._t_last is not None and now > self._t_last:
            self._positions_deg += self._speeds_deg_s * (now - self._t_last)
        self._t_last = now if self._t_last is None else max(now, self._t_last)

    def _enter(self, target: str, name: str, args: tuple, action: Callable):
        with self._lock:
            self._advance()
            call = Call(self.clock(), time.monotonic(), target, name, args, threading.current_thread().name)
            self.calls.append(call)
            try:
                if self._dropped:
                    raise FakeConnectionError(f"{name}: connection to the arm lost")
                if self._timeouts_left > 0:
                    self._timeouts_left -= 1
                    raise FakeTimeoutError(f"{name}: no reply within the timeout")
            except FakeKortexError as err:
                call.outcome = f"{type(err).__name__}: {err}"
                raise
            frozen = name in PERIODIC_CALLS and not self._unfrozen.is_set()
            freeze_timeout = self._freeze_timeout_s
        if frozen and not self._unfrozen.wait(freeze_timeout):  # outside the lock: Stop() still gets through
            call.outcome = "FakeTimeoutError: frozen"
            raise FakeTimeoutError(f"{name}: no reply within {freeze_timeout} s")
        with self._lock:
            self._advance()
            try:
                result = action()
            except FakeKortexError as err:
                call.outcome = f"{type(err).__name__}: {err}"
                raise
            call.outcome = "ok"
            return result

    def _connect(self, ip, port):
        if self.robot_ip is not None and ip != self.robot_ip:
            raise FakeConnectionError(f"no arm answers at {ip}:{port}")
        self.connected = True

    def _disconnect(self):
        self.connected = False
        self.session_open = False

    def _create_session(self, info: CreateSessionInfo):
        if not self.connected:
            raise FakeConnectionError("CreateSession: transport not connected")
        if (info.username, info.password) != self.credentials:
            raise FakeServerError("CreateSession: wrong username or password")
        self.session_open = True

    def _close_session(self):
        self.session_open = False

    def _need_session(self, name: str):
        if not (self.connected and self.session_open):
            raise FakeServerError(f"{name}: no open session")

    def _set_servoing_mode(self, mode: ServoingModeInformation):
        self._need_session("SetServoingMode")
        self.servoing_mode = mode.servoing_mode

    def _joint_speeds(self, command: JointSpeeds):
        self._need_session("SendJointSpeedsCommand")
        if self.servoing_mode != SINGLE_LEVEL_SERVOING:
            raise FakeServerError("SendJointSpeedsCommand: the arm is not in single-level servoing")
        speeds = self._speeds_deg_s.copy()
        for item in command.joint_speeds:
            i = int(item.joint_identifier)
            if not 0 <= i < N_JOINTS:
                raise FakeServerError(f"SendJointSpeedsCommand: no joint {i}")
            if not (np.isfinite(item.value) and abs(item.value) <= HARD_SPEED_LIMITS_DEG_S[i]):
                raise FakeServerError(f"SendJointSpeedsCommand: joint {i} speed {item.value} deg/s out of range")
            speeds[i] = item.value
        self._speeds_deg_s = speeds

    def _stop(self):
        self._need_session("Stop")
        self._speeds_deg_s = np.zeros(N_JOINTS)

    def _feedback(self) -> Feedback:
        self._need_session("RefreshFeedback")
        feedback = Feedback()
        for i, actuator in enumerate(feedback.actuators):
            actuator.position = float(np.mod(self._positions_deg[i], 360.0))
            actuator.velocity = float(self._speeds_deg_s[i])
            actuator.torque = 0.0
        return feedback
