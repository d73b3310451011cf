"""A Kortex API session to a Kinova Gen3: safe stops, unit conversions, one-line faults. No Drake.

Safety (the arm itself has no velocity watchdog; a speed holds until replaced):
- `KortexSession` sends `Stop()` when it opens (a crashed earlier client may
  have left a speed running) and on every exit: `close()`, the context
  manager, an atexit hook, and before raising any fault.
- A watchdog thread sends `Stop()` when no command was sent for
  `watchdog_timeout_s` (0.1 s), e.g. when the control loop hangs.
- A non-finite command, or one above the actuators' speed limits, is never
  sent: `Stop()` goes instead and a fault event is recorded.
- A failed or timed-out call, or a lost connection, sends `Stop()` (best
  effort) and raises `HardwareFault`, one line naming the arm's address, the
  call and whether `Stop()` was delivered.
- `dry_run=True` connects and reads only: no servoing-mode change, no speed
  command, no watchdog; `Stop()` at open and close as for every session.

Joint angles: the arm reports every joint in [0, 360) degrees. The limited
joints 2, 4, 6 (+-2.41, +-2.66, +-2.23 rad) map into (-pi, pi], which holds
their whole range. The continuous joints 1, 3, 5, 7 are unwrapped against the
previous reading (the first against the scenario's `q0_rad`, so a session
started at the scenario's posture reads exactly its angles, e.g. 3.735 rad
rather than -2.548 rad); this is right while a joint turns less than half a
turn between readings (at most 80 deg/s, that is over 2 s).
"""

from __future__ import annotations

import atexit
import threading
import time
from types import SimpleNamespace
from typing import Callable

import numpy as np

from rtcohand_drake.errors import InputError, one_line

KORTEX_TCP_PORT = 10000
N_JOINTS = 7
# Joints 1, 3, 5, 7 turn endlessly; 2, 4, 6 have limits inside (-pi, pi].
CONTINUOUS_JOINTS = np.array([True, False, True, False, True, False, True])
KORTEX_INSTALL_HINT = ("kortex_api is not installed: download kortex_api-2.6.0.post3-py3-none-any.whl "
                       "from Kinova and pip install it, then pip install -e '.[hardware]'")


class HardwareFault(InputError):
    """The arm or the link to it failed; the message is one line naming the arm and what failed.

    Derived from InputError so every CLI reports it as one stderr line with exit status 2.
    """


# --- angle and unit conversions --------------------------------------------------------------


def wrap_to_pi(angle_rad):
    """Angles mapped into (-pi, pi]."""
    return np.pi - np.mod(np.pi - np.asarray(angle_rad, dtype=float), 2 * np.pi)


def feedback_to_rad(position_deg, previous_rad) -> np.ndarray:
    """Joint angles (rad) from the arm's [0, 360) degree readings.

    Continuous joints take the angle nearest `previous_rad` (the previous
    reading, or a reference posture for the first one); limited joints map
    into (-pi, pi].
    """
    raw = np.radians(np.asarray(position_deg, dtype=float))
    previous = np.asarray(previous_rad, dtype=float)
    return np.where(CONTINUOUS_JOINTS, previous + wrap_to_pi(raw - previous), wrap_to_pi(raw))


def rad_s_to_deg_s(speed_rad_s) -> np.ndarray:
    return np.degrees(np.asarray(speed_rad_s, dtype=float))


def deg_s_to_rad_s(speed_deg_s) -> np.ndarray:
    return np.radians(np.asarray(speed_deg_s, dtype=float))


# --- the Kortex API, loaded only for the hardware path ---------------------------------------


def load_kortex_api() -> SimpleNamespace:
    """The kortex_api classes the station uses; a clear InputError when the package is missing."""
    try:
        from kortex_api.autogen.client_stubs.BaseClientRpc import BaseClient
        from kortex_api.autogen.client_stubs.BaseCyclicClientRpc import BaseCyclicClient
        from kortex_api.autogen.messages import Base_pb2, Session_pb2
        from kortex_api.RouterClient import RouterClient
        from kortex_api.SessionManager import SessionManager
        from kortex_api.TCPTransport import TCPTransport
    except ImportError as err:
        raise InputError(f"{KORTEX_INSTALL_HINT} ({err})") from None
    except AttributeError as err:  # protobuf > 3.20 on Python >= 3.10: collections.MutableMapping
        raise InputError(f"kortex_api cannot load with this protobuf ({err}): pip install -e '.[hardware]'") from None
    return SimpleNamespace(TCPTransport=TCPTransport, RouterClient=RouterClient, SessionManager=SessionManager,
                           BaseClient=BaseClient, BaseCyclicClient=BaseCyclicClient, Base_pb2=Base_pb2,
                           Session_pb2=Session_pb2)


# --- the session: connection, commands, watchdog, teardown -----------------------------------


class KortexSession:
    """A Kortex session to one arm: set-up, feedback, joint speed commands, watchdog, teardown.

    Use as a context manager (or `open()` / `close()`). `close()` is
    idempotent and always runs `Stop()`, then `CloseSession()`, then
    `transport.disconnect()`, each best effort. Every failed call sends
    `Stop()` and raises `HardwareFault`.
    """

    def __init__(self, api, robot_ip: str, *, credentials: tuple[str, str] = ("admin", "admin"),
                 dry_run: bool = False, watchdog_timeout_s: float = 0.1, watchdog_check_s: float = 0.01,
                 session_inactivity_timeout_ms: int = 60_000, connection_inactivity_timeout_ms: int = 2_000,
                 port: int = KORTEX_TCP_PORT):
        if not (np.isfinite(watchdog_timeout_s) and watchdog_timeout_s > 0 and watchdog_check_s > 0):
            raise ValueError("the watchdog needs a positive, finite timeout and check period")
        self._api = api
        self.robot_ip = robot_ip
        self._credentials = credentials
        self.dry_run = dry_run
        self.watchdog_timeout_s = watchdog_timeout_s
        self.watchdog_check_s = watchdog_check_s
        self._session_timeout_ms = session_inactivity_timeout_ms
        self._connection_timeout_ms = connection_inactivity_timeout_ms
        self._port = port
        self._transport = self._router = self._session_manager = self.base = self.base_cyclic = None
        self._lock = threading.Lock()
        self._last_command_time: float | None = None
        self._watchdog_tripped = False
        self._connection_error: str | None = None
        self._events: list[tuple[float, str, str]] = []  # (time.monotonic(), kind, detail)
        self._halt = threading.Event()
        self._watchdog: threading.Thread | None = None
        self.is_open = False
        self._closed = False

    # -- set-up and teardown ------------------------------------------------------------------

    def open(self) -> KortexSession:
        api = self._api
        atexit.register(self.close)  # the last resort for an exit path that skipped close()
        try:
            self._transport = api.TCPTransport()
            self._router = api.RouterClient(self._transport, self._on_router_error)
            self._transport.connect(self.robot_ip, self._port)
        except Exception as err:
            self.close()
            raise HardwareFault(f"Kinova arm at {self.robot_ip}: cannot connect on TCP port {self._port}: "
                                f"{_describe(err)}") from None
        try:
            info = api.Session_pb2.CreateSessionInfo()
            info.username, info.password = self._credentials
            info.session_inactivity_timeout = self._session_timeout_ms
            info.connection_inactivity_timeout = self._connection_timeout_ms
            self._session_manager = api.SessionManager(self._router)
            self._session_manager.CreateSession(info)
        except Exception as err:
            self.close()
            raise HardwareFault(f"Kinova arm at {self.robot_ip}: cannot open a session "
                                f"(check the username and password): {_describe(err)}") from None
        self.base = api.BaseClient(self._router)
        self.base_cyclic = api.BaseCyclicClient(self._router)
        self.is_open = True
        try:
            # Halt anything an earlier client left running before taking over.
            self.stop()
            if not self.dry_run:
                mode = api.Base_pb2.ServoingModeInformation()
                mode.servoing_mode = api.Base_pb2.SINGLE_LEVEL_SERVOING
                self._call("SetServoingMode", self.base.SetServoingMode, mode)
                self._watchdog = threading.Thread(target=self._watch, name="kortex-watchdog", daemon=True)
                self._watchdog.start()
        except BaseException:
            self.close()
            raise
        return self

    def close(self) -> None:
        """Stop(), CloseSession(), disconnect(): each best effort, once."""
        with self._lock:
            if self._closed:
                return
            self._closed = True
        try:
            self._halt.set()
            if self._watchdog is not None and self._watchdog is not threading.current_thread():
                self._watchdog.join(timeout=1.0)  # it may be inside a Stop() of its own; that one is fine
            if self.base is not None:
                self._stop_quietly()
            if self._session_manager is not None and self.is_open:
                _quietly(self._session_manager.CloseSession)
            if self._transport is not None:
                _quietly(self._transport.disconnect)
        except BaseException:  # a second Ctrl-C during teardown: the atexit hook tries again
            self._closed = False
            raise
        self.is_open = False
        atexit.unregister(self.close)

    def __enter__(self) -> KortexSession:
        return self.open()

    def __exit__(self, *exc) -> bool:
        self.close()
        return False

    # -- commands and feedback ----------------------------------------------------------------

    def read_feedback(self) -> tuple[np.ndarray, np.ndarray]:
        """(positions in [0, 360) degrees, velocities in deg/s) of the seven actuators."""
        feedback = self._call("RefreshFeedback", self.base_cyclic.RefreshFeedback)
        actuators = feedback.actuators
        if len(actuators) < N_JOINTS:
            self._fault(f"RefreshFeedback returned {len(actuators)} actuators, expected {N_JOINTS}")
        position = np.array([actuators[i].position for i in range(N_JOINTS)], dtype=float)
        velocity = np.array([actuators[i].velocity for i in range(N_JOINTS)], dtype=float)
        if not (np.all(np.isfinite(position)) and np.all(np.isfinite(velocity))):
            self._fault("RefreshFeedback returned non-finite joint angles or speeds")
        return position, velocity

    def send_joint_speeds(self, speed_deg_s) -> None:
        """Sends one JointSpeeds command (deg/s, joints 0..6, duration 0)."""
        if self.dry_run:
            raise RuntimeError("a dry-run session sends no motion")
        command = self._api.Base_pb2.JointSpeeds()
        for i, value in enumerate(np.asarray(speed_deg_s, dtype=float)):
            command.joint_speeds.add(joint_identifier=i, value=float(value), duration=0)
        self._call("SendJointSpeedsCommand", self.base.SendJointSpeedsCommand, command)
        with self._lock:
            self._last_command_time = time.monotonic()
            self._watchdog_tripped = False

    def stop(self) -> None:
        """Stop(); a failure raises HardwareFault. The watchdog then has nothing to watch."""
        self._call("Stop", self.base.Stop)
        with self._lock:
            self._last_command_time = None

    def record_event(self, kind: str, detail: str) -> None:
        with self._lock:
            self._events.append((time.monotonic(), kind, detail))

    def pop_events(self) -> list[tuple[float, str, str]]:
        with self._lock:
            events, self._events = self._events, []
        return events

    # -- internals ----------------------------------------------------------------------------

    def _call(self, what: str, function: Callable, *args):
        if self._closed or not self.is_open:
            raise HardwareFault(f"Kinova arm at {self.robot_ip}: {what} after the session was closed")
        if self._connection_error is not None:
            self._fault(f"connection lost ({self._connection_error})")
        try:
            return function(*args)
        except Exception as err:
            failed = "timed out" if "timeout" in f"{type(err).__name__} {err}".lower() else "failed"
            self._fault(f"{what} {failed}: {_describe(err)}")

    def _fault(self, what: str):
        delivered = self._stop_quietly() if self.base is not None else False
        outcome = ("the arm was sent Stop()" if delivered else
                   "Stop() could not be delivered: the arm may still be moving, press its emergency stop")
        self.record_event("fault", what)
        raise HardwareFault(f"Kinova arm at {self.robot_ip}: {what}; {outcome}")

    def _stop_quietly(self) -> bool:
        try:
            self.base.Stop()
            return True
        except Exception as err:
            self.record_event("fault", f"Stop() failed: {_describe(err)}")
            return False

    def _on_router_error(self, error) -> None:
        """The router reports a transport error (called from the API's own thread)."""
        self._connection_error = _describe(error)
        self.record_event("fault", f"router error: {self._connection_error}")

    def _watch(self) -> None:
        while not self._halt.wait(self.watchdog_check_s):
            with self._lock:
                last = self._last_command_time
                age = None if last is None else time.monotonic() - last
                stale = age is not None and age > self.watchdog_timeout_s and not self._watchdog_tripped
                if stale:
                    self._watchdog_tripped = True
            if stale:
                delivered = self._stop_quietly()
                self.record_event("watchdog", f"no command for {1000 * age:.0f} ms: "
                                              f"{'Stop() sent' if delivered else 'Stop() FAILED'}")


def _describe(err: BaseException) -> str:
    text = one_line(str(err))
    return f"{type(err).__name__}: {text}" if text else type(err).__name__


def _quietly(function: Callable) -> None:
    try:
        function()
    except Exception:
        pass


# --- the Drake systems -----------------------------------------------------------------------
