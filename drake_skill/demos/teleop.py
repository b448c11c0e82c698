"""Interactive demonstrations in Meshcat: the simulation's stand-in for kinesthetic teaching.

The thesis' demonstrator moves the robot's hand by hand (section 6.2). In
simulation the user drives the hand's desired pose from the Meshcat page
instead, and the demonstration is recorded exactly as the scripted
demonstrator records one: by the diagram's loggers
(``drake_skill.station.loggers.StationLoggers``, the one recording path, with
the diagram's ``ObjectSegmenter``): the measured hand pose in the object frame
at 100 Hz and 10 Hz, the segmented object cloud at 10 Hz. The session advances
the simulator from Python in 10 ms steps (it polls the page between them);
what it records is read from the logs when the recording ends.

Where: ``record_interactive`` opens drake-skill's own page
(:mod:`drake_skill.demos.teleop_page`, its URL printed): the Meshcat view
embedded, a panel with the session's state (idle, recording and its time,
demonstration k of n, the last verdict and why, the time limits), and the
keys, which act only while no text box has focus. Closing the page ends the
session as Ctrl-C does, keeping every finished demonstration.

Controls (keys on drake-skill's page; sliders and buttons in Meshcat's control panel):

===========  ======================  =========================================
slider       keys (- / +)            meaning
===========  ======================  =========================================
x [m]        S / W                   hand position in the world, m
y [m]        D / A                   (x away from the robot, y left, z up)
z [m]        Q / E
roll [deg]   J / L                   hand rotation about the world x, y, z
pitch [deg]  K / I                   axes, applied on top of the home
yaw [deg]    U / O                   orientation (0, 0, 0 = pointing down)
gripper [m]  Z / X                   finger opening
===========  ======================  =========================================

Buttons: **Record** (key R) starts recording, **Stop** (key T) ends it.
A gamepad (press one of its buttons on the page first so the browser
exposes it) moves the hand with velocities: left stick x / y, right stick
z (vertical) and yaw (horizontal), triggers close / open the gripper,
button A records, B stops.

Structure: :func:`teleop_step` is the whole input logic as a plain function
(testable with fake inputs); :class:`MeshcatTeleop` is a LeafSystem that
reads Meshcat every ``period`` seconds, applies it, and outputs
``X_WE_desired``, ``gripper_command`` and ``mode`` (0 idle, 1 recording,
2 done); :class:`TeleopSession` builds the station and the teleop system in
one diagram and records a demonstration.
"""

import dataclasses as dc
import math
from typing import Callable

import numpy as np
from pydrake.common.value import Value
from pydrake.math import RigidTransform, RollPitchYaw, RotationMatrix
from pydrake.systems.analysis import Simulator
from pydrake.systems.framework import BasicVector, DiagramBuilder, LeafSystem

from drake_skill.demos.format import ACTION_RAW_HZ as RECORD_HZ
from drake_skill.station.loggers import StationLoggers



IDLE, RECORDING, DONE = 0, 1, 2
MODE_NAMES = {IDLE: "idle", RECORDING: "recording", DONE: "done"}

#: (slider name, decrement key, increment key) for the 7 controlled values.
SLIDERS = (
    ("x [m] (S/W)", "KeyS", "KeyW"),
    ("y [m] (D/A)", "KeyD", "KeyA"),
    ("z [m] (Q/E)", "KeyQ", "KeyE"),
    ("roll [deg] (J/L)", "KeyJ", "KeyL"),
    ("pitch [deg] (K/I)", "KeyK", "KeyI"),
    ("yaw [deg] (U/O)", "KeyU", "KeyO"),
    ("gripper [m] (Z/X)", "KeyZ", "KeyX"),
)
RECORD_BUTTON, RECORD_KEY = "Record (R)", "KeyR"
STOP_BUTTON, STOP_KEY = "Stop (T)", "KeyT"
GAMEPAD_RECORD, GAMEPAD_STOP = 0, 1          # A, B on the standard mapping
GAMEPAD_LT, GAMEPAD_RT = 6, 7


@dc.dataclass
class TeleopConfig:
    """Interactive teleoperation settings.

    position_step, angle_step_deg, gripper_step: slider resolution, also the
      change per key press [m, deg, m].
    position_range: the x, y, z sliders span the home position +- this [m].
    angle_range_deg: the roll, pitch, yaw sliders span +- this [deg].
    gripper_max: largest finger opening [m].
    gamepad_speed, gamepad_angular_speed_deg, gamepad_gripper_speed: velocities
      at full stick / trigger [m/s, deg/s, m/s]; gamepad_deadband: stick values
      below it are ignored.
    period: how often the teleop system reads Meshcat [s].
    realtime_rate: simulation speed relative to the wall clock (1: real time).
    max_wait: give up waiting for Record after this long [s of simulation].
    max_duration: a recording stops by itself after this long [s].
    record_perception: render and segment the camera at 10 Hz while recording.
    """

    position_step: float = 0.005
    angle_step_deg: float = 2.0
    gripper_step: float = 0.005
    position_range: float = 0.5
    angle_range_deg: float = 180.0
    gripper_max: float = 0.08
    gamepad_speed: float = 0.15
    gamepad_angular_speed_deg: float = 45.0
    gamepad_gripper_speed: float = 0.05
    gamepad_deadband: float = 0.1
    period: float = 0.01
    realtime_rate: float = 1.0
    max_wait: float = 600.0
    max_duration: float = 120.0
    record_perception: bool = True


@dc.dataclass
class TeleopInputs:
    """One reading of the user's inputs.

    sliders: (7,) x, y, z [m, world], roll, pitch, yaw [deg, about world axes
    on top of the home orientation], gripper [m]; record_clicks, stop_clicks:
    the buttons' click counts; gamepad_axes: (>= 4,) in [-1, 1] or None when no
    gamepad; gamepad_buttons: (>= 8,) in [0, 1] or None; key_steps: (7,) net key
    presses per value since the last reading (drake-skill's page,
    :mod:`drake_skill.demos.teleop_page`), each one ``key_step`` [m, deg, m], or None.
    """

    sliders: np.ndarray
    record_clicks: int = 0
    stop_clicks: int = 0
    gamepad_axes: np.ndarray | None = None
    gamepad_buttons: np.ndarray | None = None
    key_steps: np.ndarray | None = None


@dc.dataclass
class TeleopState:
    """target: (7,) as TeleopInputs.sliders; mode: IDLE / RECORDING / DONE;
    seen_record, seen_stop: click counts already handled; gamepad_pressed: (2,)
    record / stop gamepad buttons held at the previous step (edge detection)."""

    target: np.ndarray
    mode: int = IDLE
    seen_record: int = 0
    seen_stop: int = 0
    gamepad_pressed: np.ndarray = dc.field(default_factory=lambda: np.zeros(2))

    def to_vector(self) -> np.ndarray:
        return np.r_[self.target, self.mode, self.seen_record, self.seen_stop, self.gamepad_pressed]

    @classmethod
    def from_vector(cls, v) -> "TeleopState":
        v = np.asarray(v, dtype=float)
        return cls(v[:7].copy(), int(round(v[7])), int(round(v[8])), int(round(v[9])), v[10:12].copy())


STATE_SIZE = 12


def key_step(config: TeleopConfig) -> np.ndarray:
    """(7,) the change of each value per key press, also the sliders' resolution [m, deg, m]."""
    return np.r_[[config.position_step] * 3, [config.angle_step_deg] * 3, config.gripper_step]


def slider_limits(X_WE_home: RigidTransform, config: TeleopConfig) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(lower (7,), upper (7,), step (7,)) of the sliders around the home pose."""
    p = X_WE_home.translation()
    r, a = config.position_range, config.angle_range_deg
    lower = np.r_[p - r, -a, -a, -a, 0.0]
    upper = np.r_[p + r, a, a, a, config.gripper_max]
    return lower, upper, key_step(config)


def teleop_step(state: TeleopState, inputs: TeleopInputs, dt: float, config: TeleopConfig,
                lower: np.ndarray, upper: np.ndarray) -> tuple[TeleopState, bool]:
    """One update of the teleoperation logic (plain numpy).

    The sliders are the target (Meshcat's own keys move the sliders in the
    browser); drake-skill's page adds its key presses (``key_steps`` *
    :func:`key_step`) and a gamepad adds velocity * dt on top. Record clicks start recording from
    IDLE, stop clicks end it; clicks in other modes are consumed and ignored.
    Returns the new state and whether the target moved away from the sliders
    (the caller then writes the target back to the sliders).
    """
    target = np.clip(np.asarray(inputs.sliders, dtype=float), lower, upper)
    moved = False
    record = inputs.record_clicks > state.seen_record
    stop = inputs.stop_clicks > state.seen_stop
    pressed = state.gamepad_pressed.copy()
    if inputs.key_steps is not None and np.any(inputs.key_steps != 0):
        target = np.clip(target + np.asarray(inputs.key_steps) * key_step(config), lower, upper)
        moved = True
    if inputs.gamepad_axes is not None and len(inputs.gamepad_axes) >= 4:
        axes = np.asarray(inputs.gamepad_axes, dtype=float)[:4]
        axes = np.where(np.abs(axes) < config.gamepad_deadband, 0.0, axes)
        buttons = np.zeros(8)
        if inputs.gamepad_buttons is not None:
            b = np.asarray(inputs.gamepad_buttons, dtype=float)[:8]
            buttons[:b.size] = b
        v = np.zeros(7)
        # Stick up is negative in the browser's Gamepad API.
        v[0] = -axes[1] * config.gamepad_speed
        v[1] = -axes[0] * config.gamepad_speed
        v[2] = -axes[3] * config.gamepad_speed
        v[5] = -axes[2] * config.gamepad_angular_speed_deg
        v[6] = (buttons[GAMEPAD_RT] - buttons[GAMEPAD_LT]) * config.gamepad_gripper_speed
        if np.any(v != 0):
            target = np.clip(target + v * dt, lower, upper)
            moved = True
        now = buttons[[GAMEPAD_RECORD, GAMEPAD_STOP]] > 0.5
        record |= bool(now[0] and not pressed[0])
        stop |= bool(now[1] and not pressed[1])
        pressed = now.astype(float)
    mode = state.mode
    if record and mode == IDLE:
        mode = RECORDING
    elif stop and mode == RECORDING:
        mode = DONE
    new = TeleopState(target, mode, max(state.seen_record, int(inputs.record_clicks)),
                      max(state.seen_stop, int(inputs.stop_clicks)), pressed)
    return new, moved


def target_pose(target: np.ndarray, R_WE_home: RotationMatrix) -> RigidTransform:
    """X_WE of a target (7,): world rotation roll-pitch-yaw [deg] applied to the home orientation."""
    R = RollPitchYaw(np.deg2rad(target[3:6])).ToRotationMatrix() @ R_WE_home
    return RigidTransform(R, target[:3])


class MeshcatTeleop(LeafSystem):
    """Reads Meshcat sliders, buttons and gamepad; outputs the hand command.

    Output ports: ``X_WE_desired`` (RigidTransform, world), ``gripper_command``
    [1] (m), ``mode`` [1] (0 idle, 1 recording, 2 done). The state (target,
    mode, handled click counts) is the system's discrete state, updated every
    ``config.period`` s; Meshcat is only read (and its sliders written back
    when a key or the gamepad moved the target).

    page: a :class:`~drake_skill.demos.teleop_page.TeleopPage` whose keys
    drive the hand; Meshcat's sliders and buttons then get no keys of their
    own (Meshcat's key bindings ignore what has focus). Without a page, the
    keys are bound on Meshcat's page.
    """

    def __init__(self, meshcat, X_WE_home: RigidTransform, config: TeleopConfig | None = None,
                 gripper_home: float = 0.0, page=None):
        super().__init__()
        self._meshcat = meshcat
        self._page = page
        self._config = config or TeleopConfig()
        self._R_home = X_WE_home.rotation()
        self._lower, self._upper, self._step = slider_limits(X_WE_home, self._config)
        self._home = np.r_[X_WE_home.translation(), 0.0, 0.0, 0.0, gripper_home]
        initial = TeleopState(self._home.copy())
        self._state = self.DeclareDiscreteState(initial.to_vector())
        self.DeclarePeriodicDiscreteUpdateEvent(self._config.period, 0.0, self._update)
        self.DeclareAbstractOutputPort("X_WE_desired", lambda: Value(RigidTransform()), self._calc_pose,
                                       {self.xd_ticket()})
        self.DeclareVectorOutputPort("gripper_command", 1, self._calc_gripper, {self.xd_ticket()})
        self.DeclareVectorOutputPort("mode", 1, self._calc_mode, {self.xd_ticket()})
        self.add_controls()

    @property
    def config(self) -> TeleopConfig:
        return self._config

    def add_controls(self) -> None:
        """Adds (or resets) the sliders at the home pose and the buttons with zero clicks."""
        m, keyed = self._meshcat, self._page is None
        existing = set(m.GetSliderNames())
        for i, (name, dec, inc) in enumerate(SLIDERS):
            if name in existing:
                m.SetSliderValue(name, self._home[i])
            else:
                m.AddSlider(name, self._lower[i], self._upper[i], self._step[i], self._home[i],
                            *((dec, inc) if keyed else ()))
        m.AddButton(RECORD_BUTTON, RECORD_KEY if keyed else "")   # re-adding resets the click count to zero
        m.AddButton(STOP_BUTTON, STOP_KEY if keyed else "")
        if self._page is not None:
            self._page.take_key_steps()
            self._page.reset_clicks()

    def read_inputs(self) -> TeleopInputs:
        m = self._meshcat
        sliders = np.array([m.GetSliderValue(name) for name, _, _ in SLIDERS])
        gamepad = m.GetGamepad()
        axes = buttons = None
        if gamepad.index is not None:
            axes, buttons = np.asarray(gamepad.axes, float), np.asarray(gamepad.button_values, float)
        record, stop = m.GetButtonClicks(RECORD_BUTTON), m.GetButtonClicks(STOP_BUTTON)
        steps = None
        if self._page is not None:
            steps = self._page.take_key_steps()
            page_record, page_stop = self._page.clicks()
            record, stop = record + page_record, stop + page_stop
        return TeleopInputs(sliders, record, stop, axes, buttons, steps)

    def state(self, context) -> TeleopState:
        return TeleopState.from_vector(context.get_discrete_state(self._state).value())

    def _update(self, context, discrete_state):
        state, moved = teleop_step(self.state(context), self.read_inputs(), self._config.period,
                                   self._config, self._lower, self._upper)
        if moved:
            for i, (name, _, _) in enumerate(SLIDERS):
                self._meshcat.SetSliderValue(name, state.target[i])
        discrete_state.set_value(self._state, state.to_vector())

    def _calc_pose(self, context, output):
        output.set_value(target_pose(self.state(context).target, self._R_home))

    def _calc_gripper(self, context, output: BasicVector):
        output.SetAtIndex(0, self.state(context).target[6])

    def _calc_mode(self, context, output: BasicVector):
        output.SetAtIndex(0, float(self.state(context).mode))


def frame_teleop_view(meshcat, object_xyz) -> None:
    """Meshcat's camera behind the robot, over its right shoulder, on the object [m, world]: the
    keys then move the hand as they read on screen (W away, A left, E up)."""
    target = np.asarray(object_xyz, dtype=float) + np.array([-0.1, 0.0, 0.15])
    meshcat.SetCameraPose(target + np.array([-0.45, -1.0, 0.75]), target)


class TeleopSession:
    """The station driven by :class:`MeshcatTeleop`, one diagram and simulator.

    meshcat: a ``pydrake.geometry.Meshcat`` (``StartMeshcat()``); the station
    is drawn there and the controls are added to its page. page: drake-skill's
    own :class:`~drake_skill.demos.teleop_page.TeleopPage`, which then owns
    the keys and shows the session's state (None: keys on Meshcat's page).
    """

    def __init__(self, skill, meshcat, config: TeleopConfig | None = None, station_config=None, page=None):
        from drake_skill.station.make import make_station
        from drake_skill.skills import load_skill

        spec = load_skill(skill)
        self.skill = spec.name
        self.config = config or TeleopConfig()
        station_config = station_config or spec.station_config()
        if not self.config.record_perception:
            station_config.enable_camera = False
        self.meshcat = meshcat
        self.page = page
        builder = DiagramBuilder()
        self.station = builder.AddNamedSystem("station", make_station(station_config, meshcat=meshcat))
        home_context = self.station.CreateDefaultContext()
        X_WE_home = self.station.GetOutputPort("ee_pose").Eval(home_context)
        self.teleop = builder.AddNamedSystem("teleop", MeshcatTeleop(
            meshcat, X_WE_home, self.config, self.station.config.gripper_home, page))
        builder.Connect(self.teleop.GetOutputPort("X_WE_desired"), self.station.GetInputPort("ee_pose_desired"))
        builder.Connect(self.teleop.GetOutputPort("gripper_command"), self.station.GetInputPort("gripper_command"))
        self.segmenter = None
        if self.config.record_perception:
            from drake_skill.perception.systems import add_object_segmenter
            self.segmenter = add_object_segmenter(builder, self.station)
        self.loggers = StationLoggers(builder, self.station, RECORD_HZ, segmenter=self.segmenter,
                                      gripper_command=self.teleop.GetOutputPort("gripper_command"))
        self.diagram = builder.Build()
        self.context = self.diagram.CreateDefaultContext()
        self.simulator = Simulator(self.diagram, self.context)
        self.X_WO = None

    def reset(self, seed: int | None) -> RigidTransform:
        """Defaults, object pose from ``seed``, controls back at home; returns X_WO."""
        self.diagram.SetDefaultContext(self.context)
        self.context.SetTime(0.0)
        self.X_WO = self.station.reset(self.context, seed)
        self.loggers.clear(self.context)
        frame_teleop_view(self.meshcat, self.X_WO.translation())   # the view opens on the workspace
        self.teleop.add_controls()
        self.simulator.Initialize()
        self.simulator.AdvanceTo(0.0)
        return self.X_WO

    def mode(self) -> int:
        return self.teleop.state(self.teleop.GetMyContextFromRoot(self.context)).mode

    def _show(self, t_start: float | None = None) -> None:
        """Puts the session's state on the page (if any) and raises PageClosed if it was closed."""
        if self.page is None:
            return
        t = self.context.get_time()
        mode = MODE_NAMES[self.mode()]
        self.page.publish(mode=mode, max_wait=self.config.max_wait, max_duration=self.config.max_duration,
                          wait_left=max(self.config.max_wait - t, 0.0) if t_start is None else None,
                          recording_s=None if t_start is None else t - t_start)
        self.page.check_open()

    def record(self, seed: int, user: Callable[[float], None] | None = None, status=print):
        """Waits for Record, records until Stop, returns the Demonstration.

        ``user(t)`` is called before every simulation step with the current
        time (tests drive the sliders and buttons from it). The recording
        lasts at least 1 s (10 samples at 10 Hz) and ends on a camera frame.
        Raises TimeoutError if Record is not pressed within ``max_wait``. A
        demonstration that pressed near the reflex's limit gets a ``warning:``
        status line (``drake_skill.demos.force_margin``).
        """
        from drake_skill.demos.force_margin import margin_warnings

        config = self.config
        X_WO = self.reset(seed)
        self.simulator.set_target_realtime_rate(config.realtime_rate)
        status(f"[{self.skill}, seed {seed}] drive the hand to the start, then press "
               f"{RECORD_BUTTON} (within {config.max_wait:.0f} s); {STOP_BUTTON} ends the demonstration "
               f"(it stops by itself after {config.max_duration:.0f} s)")
        self._wait_for_record(user)
        records, t_start = self._record_until_stop(user, status)
        demo, why = self._demonstration(records, seed, X_WO, t_start)
        status(f"recorded {demo.duration:.1f} s: {'success' if demo.success else 'FAILURE'} ({why})")
        for message in margin_warnings(demo, self.station.config.reflex, f"this demonstration (seed {seed})"):
            status(f"warning: {message}")
        return demo

    def _advance(self, t: float) -> None:
        """To t [s]: the reflex, solver and divergence checks of every run (``station.recording``)."""
        from drake_skill.station.recording import advance_and_check

        advance_and_check(self.simulator, self.station, self.context, t)

    def _wait_for_record(self, user) -> None:
        """Idle until Record, advancing every ``period`` s (the checks of :meth:`_advance`;
        the logs are emptied now and then: nothing of the idle time is kept);
        TimeoutError after ``max_wait`` s."""
        t0, i = self.context.get_time(), 0
        while self.mode() == IDLE:
            t = self.context.get_time()
            self._show()
            if t > self.config.max_wait:
                raise TimeoutError(f"{RECORD_BUTTON} was not pressed within {self.config.max_wait} s")
            if user is not None:
                user(t)
            i += 1
            self._advance(t0 + i * self.config.period)
            if i % 1000 == 0:
                self.loggers.clear(self.context)

    def _record_until_stop(self, user, status):
        """Records at RECORD_HZ (frames at ACTION_HZ) from the next frame instant until Stop or
        ``max_duration``, on a frame and for at least MIN_SAMPLES frames; returns (the
        records, their start time [s])."""
        from drake_skill.demos.format import ACTION_HZ, MIN_SAMPLES

        k = int(round(RECORD_HZ / ACTION_HZ))
        frame = self.loggers.frame_period or 1.0 / ACTION_HZ
        t_start = math.ceil(self.context.get_time() / frame - 1e-9) * frame
        if user is not None:
            user(t_start)
        self._advance(t_start)
        self.loggers.start(self.context)
        status(f"recording from t = {t_start:.2f} s")
        n = 0
        while True:
            self._show(t_start)
            done = self.mode() == DONE or (n + 1) / RECORD_HZ > self.config.max_duration
            if done and n % k == 0 and n >= (MIN_SAMPLES - 1) * k:
                return self.loggers.read(self.context, n, t_start), t_start
            n += 1
            t = self.loggers.grid(n, t_start)[-1]
            if user is not None:
                user(t)
            self._advance(t)

    def _demonstration(self, records, seed: int, X_WO, t_start: float):
        """(the Demonstration of a finished recording, why its verdict); the page shows the verdict."""
        from drake_skill.demos.demonstrator import demonstration_from
        from drake_skill.demos.format import ACTION_HZ
        from drake_skill.station.success import judge_run, verdict_why

        rule = self.station.config.success
        success = judge_run(records.times, records.object_state, records.contact_force, rule)
        why = verdict_why(records.times, records.object_state, records.contact_force, rule)
        metadata = {"source": "interactive", "teleop_config": dc.asdict(self.config),
                    "recording_started_at_s": t_start,
                    "X_WO_note": "X_OE uses the ground-truth X_WO_true at the start (simulation)"}
        if self.page is not None:
            if self.page.note:
                metadata["note"] = self.page.note
            self.page.publish(mode="done", last_verdict="success" if success else "failure", last_why=why)
        return demonstration_from(records, RECORD_HZ, ACTION_HZ, self.skill, seed, X_WO, success, metadata), why


KEY_LEGEND = ("W/S x, A/D y, E/Q z\nL/J roll, I/K pitch, O/U yaw\nX/Z gripper open/close\n"
              "R record, T stop")


def open_page(meshcat, title: str, **kwargs):
    """drake-skill's teleoperation page for ``meshcat`` (:class:`~drake_skill.demos.teleop_page.TeleopPage`),
    with this module's keys; ``kwargs`` go to it (host, port, heartbeat_timeout)."""
    from drake_skill.demos.teleop_page import TeleopPage

    return TeleopPage(meshcat.web_url(), [(dec, inc) for _, dec, inc in SLIDERS], RECORD_KEY, STOP_KEY,
                      legend=KEY_LEGEND, title=title, **kwargs)


def record_interactive(skill, count: int, seed: int = 0, config: TeleopConfig | None = None,
                       meshcat=None, status=print, station_config=None, on_demo=None, user=None,
                       page=None) -> list:
    """Records ``count`` successful interactive demonstrations (a failed one is repeated
    on the next seed). Starts Meshcat if none is given, and drake-skill's teleoperation
    page (:func:`open_page`) if ``page`` is None, and prints the page's URL.

    ``on_demo(demo)`` is called with each successful demonstration as it
    ends (:func:`record_interactive_into` keeps it on disk there); ``user``
    is passed to :meth:`TeleopSession.record` (tests drive the page with it).
    Raises :class:`~drake_skill.demos.teleop_page.PageClosed` (a
    KeyboardInterrupt) when the page is closed.
    """
    if meshcat is None:
        from pydrake.geometry import StartMeshcat
        meshcat = StartMeshcat()
    own_page = page is None
    if own_page:
        from drake_skill.skills import load_skill

        page = open_page(meshcat, f"drake-skill teleoperation: {load_skill(skill).name}")
    log: list[str] = []

    def say(line: str) -> None:
        status(line)
        log.append(line)
        page.publish(log=log[-8:])

    try:
        say(f"open {page.url} in a browser (drake-skill's teleoperation page; the Meshcat view "
            f"{meshcat.web_url()} is embedded)")
        say("keys (while no text box has focus): " + KEY_LEGEND.replace("\n", ", "))
        return _record_count(TeleopSession(skill, meshcat, config, station_config=station_config, page=page),
                             count, seed, say, on_demo, user)
    finally:
        if own_page:
            page.close()


def _record_count(session: TeleopSession, count: int, seed: int, status, on_demo, user) -> list:
    demos = []
    while len(demos) < count:
        session.page.publish(demo=len(demos) + 1, count=count, kept=len(demos))
        demo = session.record(seed, user=user, status=status)
        seed += 1
        if demo.success:
            demos.append(demo)
            if on_demo is not None:
                on_demo(demo)
            session.page.publish(kept=len(demos))
            status(f"demonstration {len(demos)} of {count} kept")
        else:
            status("not a success by the ground-truth judge; once more, on the next object pose")
    return demos


class RecordingInterrupted(KeyboardInterrupt):
    """An interactive recording stopped by Ctrl-C or SIGTERM after keeping what was finished;
    ``str()`` says what was kept and where."""


def record_interactive_into(directory, skill, count: int, force: bool = False, extra=None,
                            **kwargs) -> tuple[list, list]:
    """:func:`record_interactive` with every successful demonstration written to ``directory``
    as it ends (:class:`~drake_skill.demos.format.DemoSetWriter`); returns ``(paths, demos)``.

    ``force`` replaces a set already there (the new one grows beside it and
    replaces it whole). Ctrl-C or SIGTERM keeps every finished demonstration
    (replacing the old set once one is finished), as does closing the page, and
    raises :class:`RecordingInterrupted` saying why and how many were kept. ``extra(tmp,
    demos)`` writes more files into the finished set (``demos record``'s plot);
    ``kwargs`` go to :func:`record_interactive`.
    """
    from drake_skill.common import terminate_as_interrupt
    from drake_skill.demos.format import DemoSetWriter

    writer = DemoSetWriter(directory, force=force)
    try:
        with terminate_as_interrupt():
            demos = record_interactive(skill, count, on_demo=writer.add, **kwargs)
    except KeyboardInterrupt as stop:
        from drake_skill.demos.teleop_page import PageClosed

        why = "the teleoperation page was closed" if isinstance(stop, PageClosed) else "interrupted"
        raise RecordingInterrupted(f"{why}; {writer.interrupted()}") from None
    return writer.finish(extra=None if extra is None else lambda tmp: extra(tmp, demos)), demos
