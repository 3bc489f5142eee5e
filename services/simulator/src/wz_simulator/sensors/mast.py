"""A real mast's sensors: set-up errors, clock offsets, sway, settling and a bump (issue 39).

No real sensor stands exactly where its site file says, and no sensor's clock is the truth's.
This model gives each sensor of a site the errors a field installation leaves, drawn from the
run's seed. It is off by default; ``WZ_SIM_MOUNT_ERRORS=true`` (``wz up --mount-errors``,
``wz eval --mount-errors``) turns it on.

What reaches the services
-------------------------
Only the data. :class:`~wz_simulator.sensors.rig.SensorRig` renders every frame from the
sensor's *true* pose at its capture time (:meth:`MastModel.rotation_at`,
:meth:`MastModel.mounted`) and stamps it with the sensor's own clock, while everything published
keeps the site file's nominal world: the frame metadata carries no pose, the site served on
``wz/<site>/config/site`` is the file's, and no message names an error. A detector that trusts
the nominal pose sees the errors as a field detector would: as points, pixels and targets where
it did not expect them. The node logs the drawn errors at start and ``wz eval`` writes them in
its report, for people; no service reads either.

What is modelled, and the numbers (issue 39's figures)
------------------------------------------------------
1. **Set-up error** (:class:`MountError`), per sensor: what a technician with a level, a tape
   and a compass leaves when standing a trailer up. Yaw (heading) std 1 deg, at most 3 deg: a
   hand compass or a sighting along the road. Pitch and roll std 0.5 deg, at most 1.5 deg: a
   bubble level on a bracket. East and north std 0.2 m, at most 0.5 m: the mast's foot placed
   by tape from a landmark or by a hand-held GNSS. Height std 0.1 m, at most 0.25 m: a tape
   along the mast is better than a position on the ground. Each is a normal *redrawn* until it
   lies within its bound (not clipped): clipping would pile the tail's 0.3 % (3 sigma) or 1.2 %
   (2.5 sigma) of draws exactly on the bound, an error no technician leaves more often than its
   neighbours. The standard deviation after the truncation is 0.99 sigma (at 3 sigma) and 0.95
   sigma (at 2.5 sigma).
2. **Clock offset**, per sensor: a frame captured at true time ``t`` carries the stamp
   ``t + offset``. Camera uniform in [30, 150] ms (exposure, readout, encoding and a driver
   that stamps on arrival), radar uniform in [0, 50] ms (its processing cycle), LiDAR 0 (its
   PTP-synchronised clock stamps the sweep's start).
3. **Sway** (:class:`Sway`), per mast: in wind the mast's top leans back and forth along the
   wind's bearing and twists about its axis, each a sine of one period. Amplitudes uniform in
   [0.02, 0.1] deg at the top (a 6-10 m trailer mast: 0.1 deg at 8 m is 1.4 cm), period
   uniform in [1, 4] s (the first bending mode of a telescoping mast), phases and bearing
   uniform. Sensors on one mast share it, scaled by their height over the mast's highest
   sensor (a straight stand-in for the first bending mode's shape: the base does not turn).
4. **Settling** (:class:`Settling`), per mast: the trailer's pads sink into the ground and the
   whole mast leans, linearly in time from 0, at a rate uniform in [0, 0.2] deg/h towards a
   uniform bearing (at most 0.033 deg in a 10-minute run; a night shift's drift is what
   matters). Not scaled: the trailer turns as a rigid body.
5. **Bump** (:class:`Bump`, optional): one sensor knocked round its mast (yaw, 2 deg by
   default) at a given time, and left there.

Sensors within :data:`MAST_SPAN_M` of each other (horizontally) stand on one mast: its sway
and settling are shared; a site with two poles has two.

The true pose
-------------
With ``R(pose) = Rz(yaw) Ry(-pitch) Rx(roll)`` (:meth:`wz_shared.site.Pose.rotation`), the
sensor-to-site rotation at time ``t`` is::

    R_true(t) = L(t) Rz(s twist(t)) R(nominal + set-up error + bump(t))

with ``s = z_sensor / z_top`` and ``L(t)`` the lean: a rotation by ``|v|`` about the horizontal
axis ``z x v``, where ``v = s sway(t) u_wind + settling(t) u_settle`` (``u``: unit vectors of the
bearings; the top moves along ``v``). The yaw error, the twist and the bump are rotations about
the site's vertical and so add to the pose's yaw exactly. The position is the nominal one plus
the set-up error, constant: the top's centimetre of sway is below the LiDAR's range noise.

Randomness: each sensor's error draws from ``default_rng([seed, crc32(sensor id), crc32("mount
error")])``, each mast's motion from ``[seed, crc32(its sensor ids sorted and joined by "+"),
crc32("mast motion")]``: reproducible across processes (not Python's salted ``hash``), one sensor's draw
independent of which other sensors the site has, and independent of every other stream of the
run. Draw order per sensor: yaw, pitch, roll, east, north, up, clock offset; per mast: lean
amplitude, twist amplitude, period, lean phase, twist phase, wind bearing, settling rate,
settling bearing.
"""

from __future__ import annotations

import math
import zlib
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from types import MappingProxyType
from typing import Any

import numpy as np

from wz_shared.arrays import F64
from wz_shared.self_calibration import offset_pose
from wz_shared.site import Pose, SensorMount, Site

#: Set-up error: standard deviation and bound of the yaw (heading) [deg].
YAW_STD_DEG = 1.0
YAW_MAX_DEG = 3.0
#: Set-up error: standard deviation and bound of the pitch and of the roll [deg].
TILT_STD_DEG = 0.5
TILT_MAX_DEG = 1.5
#: Set-up error: standard deviation and bound of the east and the north offsets [m].
HORIZONTAL_STD_M = 0.2
HORIZONTAL_MAX_M = 0.5
#: Set-up error: standard deviation and bound of the height offset [m].
HEIGHT_STD_M = 0.1
HEIGHT_MAX_M = 0.25
#: Clock offset by sensor kind: (low, high) of a uniform draw [s].
CLOCK_OFFSET_RANGE_S: Mapping[str, tuple[float, float]] = MappingProxyType(
    {"camera": (0.03, 0.15), "radar": (0.0, 0.05), "lidar": (0.0, 0.0)}
)
#: Sway: (low, high) of the uniform draws of the lean and twist amplitudes at the top [deg]
#: and of the period [s].
SWAY_AMPLITUDE_RANGE_DEG = (0.02, 0.1)
SWAY_PERIOD_RANGE_S = (1.0, 4.0)
#: Settling: the largest lean rate drawn [deg/h] (uniform from 0).
SETTLING_RATE_MAX_DEG_PER_H = 0.2
#: Sensors closer than this horizontally stand on one mast [m]: a trailer mast's head carries
#: its brackets within a metre or two; poles are metres apart.
MAST_SPAN_M = 2.0
#: Default yaw of a bump [deg].
DEFAULT_BUMP_YAW_DEG = 2.0

_SECONDS_PER_HOUR = 3600.0


def _generator(seed: int, name: str, stream: str) -> np.random.Generator:
    """The generator of ``(seed, name, stream)``: CRC-32 keeps it the same in every process."""
    return np.random.default_rng(
        [seed % (1 << 64), zlib.crc32(name.encode()), zlib.crc32(stream.encode())]
    )


def truncated_normal(rng: np.random.Generator, std: float, bound: float) -> float:
    """A draw of ``N(0, std^2)`` redrawn until ``|x| <= bound`` (see the module docstring)."""
    while True:
        value = float(rng.normal(0.0, std))
        if abs(value) <= bound:
            return value


@dataclass(frozen=True)
class MountError:
    """How one sensor stands and ticks apart from what its site file says.

    Attributes
    ----------
    yaw_deg, pitch_deg, roll_deg
        Added to the site file's angles [deg] (same conventions as :class:`Pose`).
    dx_m, dy_m, dz_m
        Added to its position, east, north and up [m].
    clock_offset_s
        A frame captured at true time ``t`` is stamped ``t + clock_offset_s`` [s].
    """

    yaw_deg: float = 0.0
    pitch_deg: float = 0.0
    roll_deg: float = 0.0
    dx_m: float = 0.0
    dy_m: float = 0.0
    dz_m: float = 0.0
    clock_offset_s: float = 0.0

    @classmethod
    def draw(cls, seed: int, sensor_id: str, kind: str) -> MountError:
        """The error of sensor ``sensor_id`` (of ``kind``: lidar, camera, radar) in run ``seed``."""
        rng = _generator(seed, sensor_id, "mount error")
        yaw = truncated_normal(rng, YAW_STD_DEG, YAW_MAX_DEG)
        pitch = truncated_normal(rng, TILT_STD_DEG, TILT_MAX_DEG)
        roll = truncated_normal(rng, TILT_STD_DEG, TILT_MAX_DEG)
        east = truncated_normal(rng, HORIZONTAL_STD_M, HORIZONTAL_MAX_M)
        north = truncated_normal(rng, HORIZONTAL_STD_M, HORIZONTAL_MAX_M)
        up = truncated_normal(rng, HEIGHT_STD_M, HEIGHT_MAX_M)
        low, high = CLOCK_OFFSET_RANGE_S[kind]
        offset = float(rng.uniform(low, high))
        return cls(yaw, pitch, roll, east, north, up, offset)

    def applied_to(self, pose: Pose) -> Pose:
        """``pose`` with this error added: where the sensor really stands."""
        return offset_pose(
            pose,
            yaw_deg=self.yaw_deg,
            pitch_deg=self.pitch_deg,
            roll_deg=self.roll_deg,
            x_m=self.dx_m,
            y_m=self.dy_m,
            z_m=self.dz_m,
        )

    def describe(self) -> dict[str, float]:
        """The error as a JSON-ready mapping (the ``wz eval`` report)."""
        return {
            "yaw_deg": self.yaw_deg,
            "pitch_deg": self.pitch_deg,
            "roll_deg": self.roll_deg,
            "dx_m": self.dx_m,
            "dy_m": self.dy_m,
            "dz_m": self.dz_m,
            "clock_offset_s": self.clock_offset_s,
        }

    def text(self) -> str:
        """One line for a log: the angles, the offsets and the clock."""
        return (
            f"yaw {self.yaw_deg:+.2f} deg, pitch {self.pitch_deg:+.2f} deg, roll "
            f"{self.roll_deg:+.2f} deg, east {self.dx_m:+.2f} m, north {self.dy_m:+.2f} m, up "
            f"{self.dz_m:+.2f} m, clock {1000.0 * self.clock_offset_s:+.0f} ms"
        )


@dataclass(frozen=True)
class Sway:
    """The mast's oscillation in wind, at its top.

    The top leans along the wind's bearing by ``lean_amplitude_deg sin(2 pi t / period_s +
    lean_phase_rad)`` and twists about the mast (counter-clockwise seen from above) by
    ``twist_amplitude_deg sin(2 pi t / period_s + twist_phase_rad)``.
    """

    lean_amplitude_deg: float
    twist_amplitude_deg: float
    period_s: float
    lean_phase_rad: float
    twist_phase_rad: float
    #: Bearing the top leans along (counter-clockwise from east) [deg].
    bearing_deg: float

    def lean_deg(self, t_s: float) -> float:
        """Lean of the top at ``t_s`` along :attr:`bearing_deg` [deg]."""
        return self.lean_amplitude_deg * math.sin(
            2.0 * math.pi * t_s / self.period_s + self.lean_phase_rad
        )

    def twist_deg(self, t_s: float) -> float:
        """Twist of the top at ``t_s`` [deg]."""
        return self.twist_amplitude_deg * math.sin(
            2.0 * math.pi * t_s / self.period_s + self.twist_phase_rad
        )


@dataclass(frozen=True)
class Settling:
    """The trailer sinking into the ground: the whole mast leans ``rate_deg_per_h * t``."""

    rate_deg_per_h: float
    #: Bearing the mast leans towards (counter-clockwise from east) [deg].
    bearing_deg: float

    def lean_deg(self, t_s: float) -> float:
        """Lean at simulation time ``t_s`` [deg] (0 at t = 0)."""
        return self.rate_deg_per_h * t_s / _SECONDS_PER_HOUR


@dataclass(frozen=True)
class Mast:
    """The sensors on one mast and how the mast moves.

    Attributes
    ----------
    sensor_ids
        Its sensors.
    top_z_m
        Nominal height of its highest sensor [m]: a sensor at ``z`` sways ``z / top_z_m`` as
        much as the top.
    sway, settling
        Its motion.
    """

    sensor_ids: tuple[str, ...]
    top_z_m: float
    sway: Sway
    settling: Settling

    @classmethod
    def draw(cls, seed: int, mounts: Sequence[SensorMount]) -> Mast:
        """The motion of the mast carrying ``mounts`` in run ``seed``."""
        ids = tuple(mount.sensor_id for mount in mounts)
        rng = _generator(seed, "+".join(sorted(ids)), "mast motion")
        lean = float(rng.uniform(*SWAY_AMPLITUDE_RANGE_DEG))
        twist = float(rng.uniform(*SWAY_AMPLITUDE_RANGE_DEG))
        period = float(rng.uniform(*SWAY_PERIOD_RANGE_S))
        lean_phase = float(rng.uniform(0.0, 2.0 * math.pi))
        twist_phase = float(rng.uniform(0.0, 2.0 * math.pi))
        wind = float(rng.uniform(0.0, 360.0))
        rate = float(rng.uniform(0.0, SETTLING_RATE_MAX_DEG_PER_H))
        towards = float(rng.uniform(0.0, 360.0))
        return cls(
            sensor_ids=ids,
            top_z_m=max(mount.pose.z_m for mount in mounts),
            sway=Sway(lean, twist, period, lean_phase, twist_phase, wind),
            settling=Settling(rate, towards),
        )

    def height_share(self, mount: SensorMount) -> float:
        """How much of the top's sway a sensor at its height gets (0 at the base, 1 at the top)."""
        if self.top_z_m <= 0.0:
            return 1.0
        return min(1.0, max(0.0, mount.pose.z_m / self.top_z_m))

    def turn(self, mount: SensorMount, t_s: float) -> F64:
        """The mast's turn at ``t_s`` where ``mount`` sits: ``L(t) Rz(s twist(t))``, (3, 3)."""
        share = self.height_share(mount)
        sway_rad = math.radians(share * self.sway.lean_deg(t_s))
        settle_rad = math.radians(self.settling.lean_deg(t_s))
        wind, settle = math.radians(self.sway.bearing_deg), math.radians(self.settling.bearing_deg)
        lean = np.array(
            [
                sway_rad * math.cos(wind) + settle_rad * math.cos(settle),
                sway_rad * math.sin(wind) + settle_rad * math.sin(settle),
                0.0,
            ]
        )
        # The top moves along `lean`: a rotation about z x lean by its length.
        axis = np.array([-lean[1], lean[0], 0.0])
        twist = math.radians(share * self.sway.twist_deg(t_s))
        return _rotation_about(axis) @ _rotation_about(np.array([0.0, 0.0, twist]))

    def describe(self) -> dict[str, Any]:
        """The mast as a JSON-ready mapping (the ``wz eval`` report)."""
        return {
            "sensors": list(self.sensor_ids),
            "top_z_m": self.top_z_m,
            "sway": {
                "lean_amplitude_deg": self.sway.lean_amplitude_deg,
                "twist_amplitude_deg": self.sway.twist_amplitude_deg,
                "period_s": self.sway.period_s,
                "lean_phase_rad": self.sway.lean_phase_rad,
                "twist_phase_rad": self.sway.twist_phase_rad,
                "bearing_deg": self.sway.bearing_deg,
            },
            "settling": {
                "rate_deg_per_h": self.settling.rate_deg_per_h,
                "bearing_deg": self.settling.bearing_deg,
            },
        }

    def text(self) -> str:
        """One line for a log."""
        sway, settling = self.sway, self.settling
        return (
            f"mast of {', '.join(self.sensor_ids)} (top {self.top_z_m:.1f} m): sway lean "
            f"{sway.lean_amplitude_deg:.3f} deg towards {sway.bearing_deg:.0f} deg, twist "
            f"{sway.twist_amplitude_deg:.3f} deg, period {sway.period_s:.2f} s; settling "
            f"{settling.rate_deg_per_h:.3f} deg/h towards {settling.bearing_deg:.0f} deg"
        )


def _rotation_about(rotation_vector: F64) -> F64:
    """Rodrigues: the rotation by ``|v|`` [rad] about ``v``, (3, 3); exactly I for v = 0."""
    angle = float(np.linalg.norm(rotation_vector))
    if angle == 0.0:
        return np.eye(3)
    k = rotation_vector / angle
    cross = np.array([[0.0, -k[2], k[1]], [k[2], 0.0, -k[0]], [-k[1], k[0], 0.0]])
    rotation: F64 = np.eye(3) + math.sin(angle) * cross + (1.0 - math.cos(angle)) * cross @ cross
    return rotation


@dataclass(frozen=True)
class Bump:
    """Sensor ``sensor_id`` knocked round by ``yaw_deg`` at simulation time ``at_s``."""

    sensor_id: str
    at_s: float
    yaw_deg: float = DEFAULT_BUMP_YAW_DEG

    @classmethod
    def parse(cls, text: str, *, after_s: float = 0.0) -> Bump:
        """``SENSOR@SECONDS[:DEG]``, SECONDS counted from ``after_s`` (``wz eval``: the warm-up).

        Raises
        ------
        ValueError
            When the text is not of that form, in words for the command line.
        """
        usage = f"--bump {text!r}: expected SENSOR@SECONDS[:DEG], e.g. camera-mast@300:2"
        sensor, at, rest = text.partition("@")
        if not sensor or not at:
            raise ValueError(usage)
        seconds, colon, degrees = rest.partition(":")
        try:
            at_s = float(seconds)
            yaw_deg = float(degrees) if colon else DEFAULT_BUMP_YAW_DEG
        except ValueError:
            raise ValueError(usage) from None
        if not (math.isfinite(at_s) and math.isfinite(yaw_deg)) or at_s < 0.0:
            raise ValueError(f"{usage} (SECONDS >= 0, both finite)")
        return cls(sensor, after_s + at_s, yaw_deg)

    def yaw_deg_at(self, sensor_id: str, t_s: float) -> float:
        """The bump's yaw on ``sensor_id`` at ``t_s`` [deg]: 0 before it or on another sensor."""
        return self.yaw_deg if sensor_id == self.sensor_id and t_s >= self.at_s else 0.0


def mast_groups(mounts: Sequence[SensorMount]) -> list[list[SensorMount]]:
    """The sensors grouped by mast: chains of sensors within :data:`MAST_SPAN_M` horizontally,
    in site order."""
    groups: list[list[SensorMount]] = []
    for mount in mounts:
        near = [
            group
            for group in groups
            if any(
                math.hypot(mount.pose.x_m - other.pose.x_m, mount.pose.y_m - other.pose.y_m)
                <= MAST_SPAN_M
                for other in group
            )
        ]
        merged = [mount]
        for group in near:
            merged = group + merged
            groups.remove(group)
        groups.append(merged)
    by_site_order = {mount.sensor_id: i for i, mount in enumerate(mounts)}
    for group in groups:
        group.sort(key=lambda m: by_site_order[m.sensor_id])
    return sorted(groups, key=lambda g: by_site_order[g[0].sensor_id])


@dataclass(frozen=True)
class MastModel:
    """Every sensor's set-up error and clock, each mast's motion, and an optional bump.

    Build it with :meth:`draw` (a run's seed); tests give the parts directly. A sensor with no
    entry in ``errors`` stands exactly where its site file says; one on no mast does not move.
    """

    errors: Mapping[str, MountError]
    masts: tuple[Mast, ...] = ()
    bump: Bump | None = None

    @classmethod
    def draw(cls, site: Site, seed: int, bump: Bump | None = None) -> MastModel:
        """The errors and motions of ``site``'s sensors in run ``seed``.

        Raises
        ------
        ValueError
            When ``bump`` names a sensor the site does not have.
        """
        ids = [mount.sensor_id for mount in site.sensors]
        if bump is not None and bump.sensor_id not in ids:
            raise ValueError(
                f"cannot bump sensor {bump.sensor_id!r}: site {site.site_id} has no such sensor "
                f"(its sensors: {', '.join(ids) or 'none'})"
            )
        errors = {
            mount.sensor_id: MountError.draw(seed, mount.sensor_id, mount.kind)
            for mount in site.sensors
        }
        masts = tuple(Mast.draw(seed, group) for group in mast_groups(site.sensors))
        return cls(errors=MappingProxyType(errors), masts=masts, bump=bump)

    def error(self, sensor_id: str) -> MountError:
        """The sensor's set-up error and clock offset (none when it has no entry)."""
        return self.errors.get(sensor_id, MountError())

    def clock_offset_s(self, sensor_id: str) -> float:
        """How late the sensor stamps its frames [s]."""
        return self.error(sensor_id).clock_offset_s

    def mast_of(self, sensor_id: str) -> Mast | None:
        """The mast carrying the sensor, None when it is on none."""
        for mast in self.masts:
            if sensor_id in mast.sensor_ids:
                return mast
        return None

    def mounted(self, mount: SensorMount, t_s: float = -math.inf) -> SensorMount:
        """``mount`` as it stands at ``t_s`` but for the mast's motion: its set-up error, and
        the bump once it has happened (the default, before any time: without the bump). The
        sensor models are built on it."""
        pose = self.error(mount.sensor_id).applied_to(mount.pose)
        if self.bump is not None:
            bump_deg = self.bump.yaw_deg_at(mount.sensor_id, t_s)
            if bump_deg != 0.0:
                pose = pose.model_copy(update={"yaw_deg": pose.yaw_deg + bump_deg})
        return mount.model_copy(update={"pose": pose})

    def rotation_at(self, mount: SensorMount, t_s: float) -> F64:
        """The sensor's true sensor-to-site rotation at ``t_s``, (3, 3) (the module's
        ``R_true(t)``); exactly ``mounted(mount, t_s).pose.rotation()`` on no mast."""
        base = self.mounted(mount, t_s).pose.rotation()
        mast = self.mast_of(mount.sensor_id)
        if mast is None:
            return base
        rotation: F64 = mast.turn(mount, t_s) @ base
        return rotation

    def pose_at(self, mount: SensorMount, t_s: float) -> Pose:
        """The sensor's true pose at ``t_s`` (:meth:`rotation_at` as yaw, pitch, roll)."""
        position = self.mounted(mount, t_s).pose
        rotation = self.rotation_at(mount, t_s)
        # R = Rz(yaw) Ry(-pitch) Rx(roll): R[2, 0] = sin(pitch), R[2, 1:] = cos(pitch) (sin, cos)
        # of the roll, R[:2, 0] = cos(pitch) (cos, sin) of the yaw.
        return Pose(
            x_m=position.x_m,
            y_m=position.y_m,
            z_m=position.z_m,
            yaw_deg=math.degrees(math.atan2(rotation[1, 0], rotation[0, 0])),
            pitch_deg=math.degrees(math.asin(max(-1.0, min(1.0, float(rotation[2, 0]))))),
            roll_deg=math.degrees(math.atan2(rotation[2, 1], rotation[2, 2])),
        )

    def describe(self) -> dict[str, Any]:
        """Every drawn error, mast and the bump, JSON-ready (the ``wz eval`` report)."""
        return {
            "sensors": {sensor: error.describe() for sensor, error in self.errors.items()},
            "masts": [mast.describe() for mast in self.masts],
            "bump": None
            if self.bump is None
            else {
                "sensor_id": self.bump.sensor_id,
                "at_s": self.bump.at_s,
                "yaw_deg": self.bump.yaw_deg,
            },
        }

    def lines(self) -> list[str]:
        """The drawn errors as log lines: one per sensor, one per mast, one for the bump."""
        out = [f"{sensor}: {error.text()}" for sensor, error in self.errors.items()]
        out += [mast.text() for mast in self.masts]
        if self.bump is not None:
            out.append(
                f"bump: {self.bump.sensor_id} turned {self.bump.yaw_deg:+.2f} deg at "
                f"{self.bump.at_s:g} s"
            )
        return out
