"""The ego vehicle: a kinematic bicycle model and the simple "driver" that steers it along its route.

Reference point is the rear-axle centre (DESIGN.md); axes REP-103 (x forward, y left, z up).  With
the steering angle held over a step the path has constant curvature ``tan(δ)/L``, so each step is
integrated *exactly* on a circular arc (a straight line for δ = 0) for the distance travelled at
constant acceleration: a vehicle at constant speed and zero steer travels exactly ``v·t``.

``ActuatedEgo`` is the ego under an algorithm's control (closed loop): its ``ControlCommands`` become an
acceleration through a ``PedalModel`` (throttle, brake, coasting resistance), optionally one step late,
and drive the bicycle within the actuator limits of ``EgoGeometry`` and the tyres' friction circle
(``TyreLimit``): the combined acceleration ``sqrt(a_lon² + a_lat²)`` never exceeds ``μ·g``.

The driver is not a redrive algorithm: it follows the route with pure pursuit and sets its speed with
IDM towards the set speed, stopping behind leaders, at red lights and at the end of its route.
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass
from typing import Any, cast

import numpy as np
import numpy.typing as npt

from redrive.geometry.se3 import identity_matrix
from redrive.motion import IdmParams
from redrive.sim.agents import advance_1d
from redrive.sim.roads import Route
from redrive.types import ControlCommands, VehicleState
from redrive.types._drafts import draft_class

__all__ = [
    "STANDARD_GRAVITY_MPS2",
    "ActuatedEgo",
    "BicycleModel",
    "EgoDriver",
    "EgoGeometry",
    "PedalModel",
    "TyreLimit",
    "friction_scale",
]

#: standard gravity g_n (CGPM 1901; ISO 80000-3), m/s².
STANDARD_GRAVITY_MPS2 = 9.80665


@dataclass(frozen=True, slots=True, kw_only=True)
class EgoGeometry:
    """Dimensions (metres) and actuator limits of the ego vehicle.

    ``rear_overhang_m`` is the distance from the rear bumper to the rear axle (the reference point).
    Limits: road-wheel angle ``max_steer_rad`` (rad) and its rate ``max_steer_rate_rad_s`` (rad/s);
    longitudinal acceleration within [-``max_decel_mps2``, ``max_accel_mps2``] (m/s²) and, when
    ``max_jerk_mps3`` is set, its change within ±``max_jerk_mps3`` (m/s³; ``None``: unbounded).
    """

    wheelbase_m: float = 2.8
    length_m: float = 4.7
    width_m: float = 1.9
    height_m: float = 1.5
    rear_overhang_m: float = 0.95
    max_steer_rad: float = 0.6
    max_steer_rate_rad_s: float = 0.8
    max_accel_mps2: float = 3.0
    max_decel_mps2: float = 9.0
    max_jerk_mps3: float | None = None

    @property
    def front_offset_m(self) -> float:
        """Rear axle to front bumper, metres."""
        return self.length_m - self.rear_overhang_m

    @property
    def center_offset_m(self) -> float:
        """Rear axle to the box centre (along +x of base_link), metres."""
        return self.length_m / 2.0 - self.rear_overhang_m


class BicycleModel:
    """Kinematic bicycle state: rear-axle x, y (metres, map), yaw (rad), speed (m/s), steer (rad)."""

    def __init__(
        self,
        geometry: EgoGeometry,
        *,
        x_m: float = 0.0,
        y_m: float = 0.0,
        yaw_rad: float = 0.0,
        speed_mps: float = 0.0,
        steer_rad: float = 0.0,
    ) -> None:
        self.geometry = geometry
        self.x_m, self.y_m, self.yaw_rad = float(x_m), float(y_m), float(yaw_rad)
        self.speed_mps = float(speed_mps)
        self.steer_rad = float(steer_rad)
        self.accel_mps2 = 0.0

    @property
    def curvature_1pm(self) -> float:
        """Path curvature tan(δ)/L, 1/m (left > 0)."""
        return math.tan(self.steer_rad) / self.geometry.wheelbase_m

    def step(
        self,
        dt_s: float,
        *,
        accel_mps2: float,
        steer_rad: float,
        friction_circle_mps2: float | None = None,
    ) -> None:
        """Advance ``dt_s`` seconds with a steering command (clipped to range and rate) and a
        longitudinal acceleration (clipped to the limits and, when ``max_jerk_mps3`` is set, to
        ``max_jerk_mps3 · dt_s`` from the previous step's; the vehicle never reverses).

        With ``friction_circle_mps2`` (μ·g, :class:`TyreLimit`) the combined acceleration is
        bounded too (:func:`friction_scale`): where ``sqrt(a² + (v²·tan δ / L)²)`` — ``v`` the
        step's highest speed — passes it, the acceleration and the curvature are scaled back
        onto the circle together (the tyre force keeps the direction asked for), and the steering
        angle becomes the one of that curvature: the angle the tyres hold.  None: no bound (the
        scripted driver of a synthetic world).

        Coming to rest sets the acceleration to zero at once: that is the vehicle stopping, not a
        commanded change, and the jerk bound does not apply to it.
        """
        g = self.geometry
        max_delta = g.max_steer_rate_rad_s * dt_s
        cmd = min(max(steer_rad, -g.max_steer_rad), g.max_steer_rad)
        self.steer_rad += min(max(cmd - self.steer_rad, -max_delta), max_delta)
        accel = min(max(accel_mps2, -g.max_decel_mps2), g.max_accel_mps2)
        if g.max_jerk_mps3 is not None:
            max_change = g.max_jerk_mps3 * dt_s
            accel = min(max(accel, self.accel_mps2 - max_change), self.accel_mps2 + max_change)
        if friction_circle_mps2 is not None:
            scale = friction_scale(
                self.speed_mps,
                accel_mps2=accel,
                curvature_1pm=self.curvature_1pm,
                dt_s=dt_s,
                limit_mps2=friction_circle_mps2,
            )
            if scale < 1.0:
                accel *= scale
                self.steer_rad = math.atan(math.tan(self.steer_rad) * scale)
        self.accel_mps2 = accel
        dist, self.speed_mps = advance_1d(0.0, self.speed_mps, self.accel_mps2, dt_s)
        if self.speed_mps == 0.0 and self.accel_mps2 < 0.0:
            self.accel_mps2 = 0.0
        kappa = self.curvature_1pm
        dyaw = kappa * dist
        yaw0 = self.yaw_rad
        if kappa == 0.0:
            self.x_m += dist * math.cos(yaw0)
            self.y_m += dist * math.sin(yaw0)
        else:
            self.x_m += (math.sin(yaw0 + dyaw) - math.sin(yaw0)) / kappa
            self.y_m += (math.cos(yaw0) - math.cos(yaw0 + dyaw)) / kappa
        self.yaw_rad = yaw0 + dyaw

    def state(self, stamp_ns: int) -> VehicleState:
        """The true state of the rear-axle centre in the map frame."""
        c, s = math.cos(self.yaw_rad), math.sin(self.yaw_rad)
        v, kappa = self.speed_mps, self.curvature_1pm
        lateral = v * v * kappa
        # one read-only array, its three rows the vectors (VehicleState keeps read-only views
        # as they are: no copy, no view of each made writeable-less again)
        rows = np.array(
            [
                self.x_m,
                self.y_m,
                0.0,
                v * c,
                v * s,
                0.0,
                self.accel_mps2 * c - lateral * s,
                self.accel_mps2 * s + lateral * c,
                0.0,
            ]
        )
        rows.flags.writeable = False
        # what VehicleState(...) builds of these values (an int stamp, read-only float64 (3,)
        # views, Python floats), without its checks: it runs for both worlds every frame
        state = _StateDraft()  # (redrive.types._drafts)
        state.stamp_ns = int(stamp_ns)
        state.frame_id = "map"
        state.position = rows[0:3]
        state.velocity = rows[3:6]
        state.acceleration = rows[6:9]
        state.heading_rad = math.atan2(s, c)
        state.yaw_rate_rad_s = float(v * kappa)
        state.__class__ = VehicleState
        return cast("VehicleState", state)

    def map_from_base(self) -> npt.NDArray[np.float64]:
        """4×4 float64 pose of base_link (rear-axle centre) in the map frame."""
        return pose_matrix(self.x_m, self.y_m, self.yaw_rad)


def friction_scale(
    speed_mps: float, *, accel_mps2: float, curvature_1pm: float, dt_s: float, limit_mps2: float
) -> float:
    """The factor (≤ 1) that puts the demand of one step — longitudinal ``accel_mps2`` and the
    lateral ``v²·κ`` at the step's highest speed ``v = max(v₀, v₀ + a·dt)`` — on the friction
    circle of radius ``limit_mps2``; 1 when it is inside.  Scaling both by it keeps every speed
    of the step within the bound (the lateral acceleration grows with v²)."""
    v = max(speed_mps, speed_mps + accel_mps2 * dt_s)
    lateral = v * v * curvature_1pm
    demand = math.hypot(accel_mps2, lateral)
    if demand <= limit_mps2:
        return 1.0
    return limit_mps2 / demand


@dataclass(frozen=True, slots=True, kw_only=True)
class TyreLimit:
    """The tyres' grip: the friction circle ``sqrt(a_lon² + a_lat²) ≤ μ·g`` (Kamm's circle).

    ``friction_coefficient`` (μ, default 0.9): the peak tyre–road friction of a car on dry
    asphalt or concrete in good condition — the Bosch Automotive Handbook's table of static
    friction coefficients of pneumatic tyres gives 0.75–1.0 for dry roads (new and worn tyres,
    50–130 km/h); 0.9 is the middle of that range, and the ego's pedal model brakes at 8 m/s²
    (0.82 g), inside it.  Use about 0.5 for a wet road, 0.1–0.2 for snow and ice.
    ``gravity_mps2``: standard gravity.
    """

    friction_coefficient: float = 0.9
    gravity_mps2: float = STANDARD_GRAVITY_MPS2

    def __post_init__(self) -> None:
        for name in ("friction_coefficient", "gravity_mps2"):
            value = getattr(self, name)
            if not (math.isfinite(value) and value > 0.0):
                msg = f"TyreLimit.{name} must be a positive number, got {value}"
                raise ValueError(msg)

    @property
    def max_accel_mps2(self) -> float:
        """The friction circle's radius μ·g, m/s²."""
        return self.friction_coefficient * self.gravity_mps2


@dataclass(frozen=True, slots=True, kw_only=True)
class PedalModel:
    """How throttle and brake (``ControlCommands``, each in [0, 1]) become longitudinal acceleration.

    ``a = throttle · max_accel_mps2 − brake · max_brake_mps2 − coast(v)`` with the coasting
    resistance ``coast(v) = rolling_resistance_mps2 + drag_coefficient_1pm · v²``.  With both pedals
    released the vehicle decelerates by ``coast(v)`` exactly; it never reverses (the bicycle model
    stops it at zero speed).

    Attributes:
        max_accel_mps2: acceleration at full throttle before resistance, m/s².
        max_brake_mps2: deceleration at full brake before resistance, m/s².
        rolling_resistance_mps2: rolling resistance as a deceleration, m/s² (≈ c_rr · g).
        drag_coefficient_1pm: aerodynamic drag ρ·c_d·A / (2·mass), 1/m (deceleration per v²).
    """

    max_accel_mps2: float = 3.0
    max_brake_mps2: float = 8.0
    rolling_resistance_mps2: float = 0.1
    drag_coefficient_1pm: float = 2.6e-4

    def __post_init__(self) -> None:
        for name in ("max_accel_mps2", "max_brake_mps2"):
            value = getattr(self, name)
            if not (math.isfinite(value) and value > 0.0):
                msg = f"PedalModel.{name} must be a positive number, got {value}"
                raise ValueError(msg)
        for name in ("rolling_resistance_mps2", "drag_coefficient_1pm"):
            value = getattr(self, name)
            if not (math.isfinite(value) and value >= 0.0):
                msg = f"PedalModel.{name} must be a non-negative number, got {value}"
                raise ValueError(msg)

    def coast(self, speed_mps: float) -> float:
        """Deceleration (m/s², ≥ 0) with both pedals released at ``speed_mps``."""
        return self.rolling_resistance_mps2 + self.drag_coefficient_1pm * speed_mps * speed_mps

    def acceleration(self, commands: ControlCommands, speed_mps: float) -> float:
        """Longitudinal acceleration (m/s²) that ``commands`` give at ``speed_mps``."""
        return (
            commands.throttle * self.max_accel_mps2
            - commands.brake * self.max_brake_mps2
            - self.coast(speed_mps)
        )

    def pedals(self, accel_mps2: float, speed_mps: float) -> tuple[float, float]:
        """Throttle and brake (each in [0, 1], one of them zero) that give ``accel_mps2`` at
        ``speed_mps``; beyond what the pedals can do, the nearest (full throttle or full brake)."""
        net = accel_mps2 + self.coast(speed_mps)
        if net >= 0.0:
            return min(net / self.max_accel_mps2, 1.0), 0.0
        return 0.0, min(-net / self.max_brake_mps2, 1.0)


class ActuatedEgo:
    """The ego driven by ``ControlCommands``: a :class:`BicycleModel` behind a :class:`PedalModel`.

    ``delay_steps`` is 0 (a command acts in the step it is applied) or 1 (the command applied at step
    k acts at step k+1; the first step acts on a neutral command: pedals released — coasting — and
    the steering angle held where it is).  Steering and acceleration limits (angle, rate, accel,
    decel, jerk) are those of the model's :class:`EgoGeometry`, the combined acceleration that of
    ``tyres`` (:class:`TyreLimit`, μ = 0.9 by default), enforced by :meth:`BicycleModel.step`.
    """

    def __init__(
        self,
        model: BicycleModel,
        *,
        pedals: PedalModel | None = None,
        delay_steps: int = 0,
        tyres: TyreLimit | None = None,
    ) -> None:
        if delay_steps not in (0, 1):
            msg = f"ActuatedEgo: delay_steps must be 0 or 1, got {delay_steps!r}"
            raise ValueError(msg)
        self._model = model
        self.pedals = pedals if pedals is not None else PedalModel()
        self.tyres = tyres if tyres is not None else TyreLimit()
        self.delay_steps = delay_steps
        self._pending: ControlCommands | None = None
        #: apply_steps' kernel parameters, and the (geometry, pedals, tyres) they were made of
        self._kernel_p = np.zeros(0)
        self._kernel_key: tuple[EgoGeometry, PedalModel, TyreLimit] | None = None

    @property
    def model(self) -> BicycleModel:
        """The bicycle model this ego drives (its state is the ego's true state)."""
        return self._model

    def apply(self, commands: ControlCommands, dt_s: float) -> None:
        """Advance ``dt_s`` seconds under ``commands`` (or, with a one-step delay, the previous
        step's commands)."""
        _check_step(dt_s)
        acting = commands
        if self.delay_steps == 1:
            acting = self._pending or ControlCommands(steering_angle_rad=self._model.steer_rad)
            self._pending = commands
        accel = self.pedals.acceleration(acting, self._model.speed_mps)
        self._model.step(
            dt_s,
            accel_mps2=accel,
            steer_rad=acting.steering_angle_rad,
            friction_circle_mps2=self.tyres.max_accel_mps2,
        )

    def apply_steps(self, commands: ControlCommands, dt_s: float, steps: int) -> None:
        """``steps`` × :meth:`apply` ``(commands, dt_s)``: without a delay in one compiled call
        (:func:`redrive.sim.stepper.pedal_steps`, the world's own commanded-ego step: the same
        doubles as the Python steps), with one as ``steps`` calls of :meth:`apply`."""
        _check_step(dt_s)
        if self.delay_steps or steps < 1:
            for _ in range(steps):
                self.apply(commands, dt_s)
            return
        from redrive.sim import stepper  # (numba is imported on first use)

        m = self._model
        key = (m.geometry, self.pedals, self.tyres)
        if self._kernel_key is None or any(
            a is not b for a, b in zip(self._kernel_key, key, strict=True)
        ):
            self._kernel_p = stepper.ego_parameters(
                m.geometry, self.pedals, self.tyres.max_accel_mps2
            )
            self._kernel_key = key
        p = self._kernel_p
        p[stepper.THROTTLE] = commands.throttle
        p[stepper.BRAKE] = commands.brake
        p[stepper.STEER_CMD] = commands.steering_angle_rad
        e = np.array([m.x_m, m.y_m, m.yaw_rad, m.speed_mps, m.steer_rad, m.accel_mps2, 0.0])
        stepper.pedal_steps(e, p, dt_s, steps)
        m.x_m, m.y_m, m.yaw_rad, m.speed_mps, m.steer_rad, m.accel_mps2, _ = e.tolist()

    def brake(self, dt_s: float) -> None:
        """Advance ``dt_s`` seconds under a full emergency brake with the steering angle held —
        the fallback for a frame whose algorithm failed.  It is a command like any other: with a
        one-step delay it acts one step later."""
        hold = ControlCommands(throttle=0.0, brake=1.0, steering_angle_rad=self._model.steer_rad)
        self.apply(hold, dt_s)

    def state(self, stamp_ns: int) -> VehicleState:
        """The ego's true state (rear-axle centre, map frame) at ``stamp_ns``."""
        return self._model.state(stamp_ns)

    def describe(self) -> dict[str, Any]:
        """Every parameter of the ego's motion, for the run manifest."""
        return {
            "motion_model": "kinematic_bicycle",
            "geometry": asdict(self._model.geometry),
            "pedals": asdict(self.pedals),
            "tyres": {**asdict(self.tyres), "friction_circle_mps2": self.tyres.max_accel_mps2},
            "delay_steps": self.delay_steps,
        }


def _check_step(dt_s: float) -> None:
    if not (math.isfinite(dt_s) and dt_s > 0.0):
        msg = f"ActuatedEgo.apply: dt_s must be a positive number of seconds, got {dt_s}"
        raise ValueError(msg)


#: VehicleState's draft (:mod:`redrive.types._drafts`): BicycleModel.state builds its states
#: unchecked
_StateDraft = draft_class(VehicleState)


def pose_matrix(x_m: float, y_m: float, yaw_rad: float) -> npt.NDArray[np.float64]:
    """4×4 float64 planar pose: rotation ``yaw_rad`` about +z, translation (x, y, 0) metres."""
    c, s = math.cos(yaw_rad), math.sin(yaw_rad)
    out = identity_matrix()
    out[0, 0], out[0, 1], out[1, 0], out[1, 1] = c, -s, s, c
    out[0, 3], out[1, 3] = x_m, y_m
    return out


class EgoDriver:
    """Pure pursuit on ``route`` and IDM towards ``idm.desired_speed_mps`` (the set speed).

    The lookahead distance is ``clip(lookahead_time_s · v, min_lookahead_m, max_lookahead_m)``.
    The world's frame kernel (:mod:`redrive.sim.stepper`) drives with these parameters and state;
    the same driver in plain Python, the reference it is compared with, is
    ``tests/sim/_reference_agents.py``.
    """

    def __init__(
        self,
        route: Route,
        s_m: float,
        *,
        idm: IdmParams,
        ego_id: int = 0,
        lookahead_time_s: float = 0.8,
        min_lookahead_m: float = 4.0,
        max_lookahead_m: float = 25.0,
    ) -> None:
        self.route = route
        self.s_m = float(s_m)
        self.idm = idm
        self.ego_id = ego_id
        self.lookahead_time_s = lookahead_time_s
        self.min_lookahead_m = min_lookahead_m
        self.max_lookahead_m = max_lookahead_m
        self._committed: set[int] = set()
