"""A stand-in for Haply's Inverse Service: a real WebSocket server on loopback speaking the
simulation channel's 3.x JSON format, with an emulated Inverse3 whose cursor a spring
"hand" holds and the commanded force moves.

Written from Haply's documentation only (docs.haply.co/inverseSDK/service/: `api/simulation`,
`realtime/websocket-protocol`, `realtime/control-commands`, `commons/types`, `commons/basis`,
`commons/mount-and-workspace`, `session-configuration/sessions`,
`session-configuration/device-config`, `tutorials/06-combined`). Behaviour modelled:
- on connect, one inventory: `session_id`, and per device `device_id`, `config` (type,
  handedness, preset, basis), `state`, `status`; a wireless VerseGrip beside it;
- then exactly one state update (state and status of every device) per client message,
  and nothing unasked;
- `set_cursor_force` with `vector` {x, y, z} in newtons is rendered until the next message;
  a message that does not command the device (or a `set_cursor_force` without `vector`,
  counted in `ignored_commands`) idles it, and so does silence: IDLE_AFTER_S without a
  message (the docs give no figure: ours);
- positions in metres, velocities in m/s, in Haply's frame: +X right, +Y forward (away
  from the user), +Z up; the origin is the device base unless the session's device
  `configure.preset` is `arm_front_centered` (or `led_front_centered`), which moves it
  to the workspace centre; configuration is per session and dies with the connection.
Not modelled: the HTTP API, basis permutations and mounts (recorded, not applied),
position control, several arms. `answer_after_s` makes a slow service: each state update
leaves that long after its message came (the state as it was when the message was taken),
in order, while later messages are taken meanwhile.

The hand, the cursor and every force here are in Haply's frame, millimetres for the
hand and cursor (tests/emulators/physics.py), the workspace centre at the origin.
"""

from __future__ import annotations

import json
import threading
import time
from collections import deque

import numpy as np
from websockets.exceptions import ConnectionClosed
from websockets.sync.server import serve

from tests.emulators.physics import HeldStylus, MovableHand

DEVICE_ID = "049D"
GRIP_ID = "61548"
IDLE_AFTER_S = 0.05
# Where the workspace centre lies seen from the base, m: the resting cursor of the docs'
# example inventory (realtime/websocket-protocol), taken as the centre (ours).
CENTRE_FROM_BASE_M = (0.0, -0.12, 0.15)
CENTRED_PRESETS = ("arm_front_centered", "led_front_centered")


def _xyz(v) -> dict:
    return {"x": float(v[0]), "y": float(v[1]), "z": float(v[2])}


class InverseService:
    """The service on 127.0.0.1:`port` (0: any free port); `hand.target` (mm, Haply frame,
    about the workspace centre) moves the user's hand."""

    def __init__(
        self,
        port: int = 0,
        *,
        kind: str = "inverse3",
        calibrated: bool = True,
        hand_stiffness_n_per_mm: float = 0.5,
        grip: bool = True,
        answer_after_s: float = 0.0,
    ):
        self.kind, self.calibrated, self.grip = kind, calibrated, grip
        self.answer_after_s = answer_after_s
        self.hand = MovableHand((0.0, 0.0, 0.0))
        self.stylus = HeldStylus(
            (0.0, 0.0, 0.0), self.hand, hand_stiffness_n_per_mm=hand_stiffness_n_per_mm
        )
        self.grip_buttons = {"a": False, "b": False, "c": False}
        self.grip_orientation = (0.0, 0.0, 0.0, 1.0)  # x, y, z, w
        self.lock = threading.Lock()
        self._force = np.zeros(3)
        self._commanded_at = 0.0
        self.samples: deque = deque(maxlen=20000)  # (t_ns, force N, cursor mm): one per message
        self.messages = self.ignored_commands = self.sessions = 0
        self.presets: list[str] = []
        self.profiles: list[str] = []
        self.basis_changes = 0
        self._awake = threading.Event()
        self._awake.set()
        self._connections: set = set()
        self._running = True
        self._ticker = threading.Thread(target=self._tick, daemon=True)
        self._ticker.start()
        self.port = port
        self._server = None
        self.start()

    # the service ----------------------------------------------------------------------
    def start(self) -> None:
        self._server = serve(
            self._handle, "127.0.0.1", self.port, compression=None, ping_interval=None
        )
        self.port = self._server.socket.getsockname()[1]
        threading.Thread(target=self._server.serve_forever, daemon=True).start()

    def stop(self) -> None:
        """The service goes away: the port closes and every connection with it."""
        if self._server is not None:
            self._server.shutdown()
            self._server = None
        self.drop_connections()

    def drop_connections(self) -> None:
        for conn in list(self._connections):
            conn.close()

    def hang(self) -> None:
        """Stop answering: messages wait, unanswered, until `resume()`."""
        self._awake.clear()

    def resume(self) -> None:
        self._awake.set()

    @property
    def url(self) -> str:
        return f"ws://127.0.0.1:{self.port}"

    @property
    def device_spec(self) -> str:
        return f"inverse3:{self.url}"

    @property
    def env(self) -> dict[str, str]:
        return {"SASPROBE_INVERSE_SERVICE": self.url}

    def close(self) -> None:
        self._running = False
        self.resume()
        self.stop()

    # the arm --------------------------------------------------------------------------
    def _tick(self) -> None:
        while self._running:
            with self.lock:
                if time.monotonic() - self._commanded_at > IDLE_AFTER_S:
                    self._force = np.zeros(3)
                self.stylus.advance(self._force)
            time.sleep(0.001)

    def motor_force(self) -> np.ndarray:
        with self.lock:
            return self._force.copy()

    def _state(self, centred: bool, full: bool) -> dict:
        with self.lock:
            cursor_m = self.stylus.now() / 1000.0
            velocity = self.stylus.velocity / 1000.0
            force = self._force.copy()
        if not centred:
            cursor_m = cursor_m + np.asarray(CENTRE_FROM_BASE_M)
        inverse3 = {
            "device_id": DEVICE_ID,
            "state": {
                "cursor_position": _xyz(cursor_m),
                "cursor_velocity": _xyz(velocity),
                "current_cursor_force": _xyz(force),
                "control_mode": "force" if np.any(force) else "idle",
            },
            "status": {
                "calibrated": self.calibrated,
                "ready": True,
                "started": True,
                "power_supply": True,
            },
        }
        message = {"inverse3": [inverse3]}
        if full:
            inverse3["config"] = {
                "type": self.kind,
                "handedness": "right",
                "preset": "defaults",
                "basis": {"permutation": "XYZ"},
            }
        if self.grip:
            x, y, z, w = self.grip_orientation
            grip = {
                "device_id": GRIP_ID,
                "state": {
                    "buttons": dict(self.grip_buttons),
                    "orientation": {"x": x, "y": y, "z": z, "w": w},
                },
            }
            if full:
                grip["config"] = {"type": "wireless_verse_grip"}
            message["wireless_verse_grip"] = [grip]
        return message

    def _apply(self, text) -> str | None:
        """One client message: the force it commands, and the preset it names (if any)."""
        try:
            message = json.loads(text)
        except ValueError:
            message = {}
        message = message if isinstance(message, dict) else {}
        session = message.get("session") if isinstance(message.get("session"), dict) else {}
        configure = session.get("configure") if isinstance(session.get("configure"), dict) else {}
        if isinstance(configure.get("profile"), dict):
            self.profiles.append(str(configure["profile"].get("name")))
        if "basis" in configure:
            self.basis_changes += 1
        force, named = np.zeros(3), None
        for entry in message.get("inverse3") or ():
            if not isinstance(entry, dict) or entry.get("device_id") != DEVICE_ID:
                continue
            device_configure = (
                entry.get("configure") if isinstance(entry.get("configure"), dict) else {}
            )
            preset = device_configure.get("preset")
            if isinstance(preset, dict) and "preset" in preset:
                named = str(preset["preset"])
                self.presets.append(named)
            commands = entry.get("commands") if isinstance(entry.get("commands"), dict) else {}
            command = commands.get("set_cursor_force")
            if isinstance(command, dict):
                vector = command.get("vector")
                try:
                    force = np.array([float(vector[k]) for k in ("x", "y", "z")])
                except (TypeError, KeyError, ValueError):
                    self.ignored_commands += 1
                    force = np.zeros(3)
                if not np.all(np.isfinite(force)):
                    force = np.zeros(3)
        with self.lock:
            self.stylus.advance(self._force)  # the old force acted until now
            self._force = force
            self._commanded_at = time.monotonic()
            self.samples.append((time.monotonic_ns(), force.copy(), self.stylus.now()))
            self.messages += 1
        return named

    def _handle(self, conn) -> None:
        self._connections.add(conn)
        self.sessions += 1
        session_id = self.sessions
        centred = False  # the session's preset: "defaults" until it names another
        answers = _Answers(conn, self.answer_after_s)
        try:
            conn.send(json.dumps({"session_id": session_id, **self._state(centred, full=True)}))
            for text in conn:
                self._awake.wait()
                if not self._running:
                    return
                named = self._apply(text)
                if named is not None:
                    centred = named in CENTRED_PRESETS
                answers.send(
                    json.dumps({"session_id": session_id, **self._state(centred, full=False)})
                )
        except ConnectionClosed:
            pass
        finally:
            answers.close()
            self._connections.discard(conn)


class _Answers:
    """A connection's state updates: sent at once, or `delay_s` after their message came (in
    order, from a thread of their own)."""

    def __init__(self, conn, delay_s: float):
        self.conn, self.delay_s = conn, delay_s
        self.queue: deque = deque()
        self.ready = threading.Condition()
        self.open = True
        if delay_s > 0:
            threading.Thread(target=self._run, daemon=True).start()

    def send(self, text: str) -> None:
        if self.delay_s <= 0:
            self.conn.send(text)
            return
        with self.ready:
            self.queue.append((time.monotonic() + self.delay_s, text))
            self.ready.notify()

    def _run(self) -> None:
        while True:
            with self.ready:
                while self.open and not self.queue:
                    self.ready.wait()
                if not self.open:
                    return
                due, text = self.queue.popleft()
            time.sleep(max(0.0, due - time.monotonic()))
            try:
                self.conn.send(text)
            except ConnectionClosed:
                return

    def close(self) -> None:
        with self.ready:
            self.open = False
            self.ready.notify()


def launch(**options) -> InverseService:
    return InverseService(**options)
