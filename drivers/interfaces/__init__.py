"""Abstract device interfaces: what the rest of the station may know about hardware.

``station`` (the sequencer, compensation, vision) talks only to these classes, so a
real drive, a drive pointed at a twin server and a test double are interchangeable.
Every method that touches I/O is ``async`` and bounded by a timeout: a controller
that hangs on a dead cable is worse than one that reports the dead cable.

Errors are typed so that a caller can decide what to do without parsing messages:

* :class:`DeviceTimeout` -- the device did not answer in time (retry may help);
* :class:`CommunicationLost` -- the link is gone (reconnect, or stop the station);
* :class:`ProtocolError` -- an answer arrived but was malformed or failed its checksum;
* :class:`DriveFault` -- the drive answered and reports a fault code;
* :class:`FollowingError` -- a drive fault of the special kind "the axis did not follow".

The axes' abstract base is :class:`ServoAxis` (:class:`LinearAxis` in mm,
:class:`RotaryAxis` in deg); a caller that needs only one verb of a device may ask
for the small protocols instead (:mod:`drivers.interfaces.protocols`:
:class:`Movable`, :class:`Locatable`, :class:`Stoppable`, :class:`Readable`). The
logic of one move (its check, its timeout) is :class:`MoveLogic`
(:mod:`drivers.interfaces.move_logic`).
"""

from __future__ import annotations

import abc
import math
import enum
from dataclasses import dataclass, field

import numpy as np

from drivers.interfaces.move_logic import MoveLogic
from drivers.interfaces.protocols import UNITS, Locatable, Location, Movable, Readable, Stoppable, Units

__all__ = [
    # errors
    "DriverError", "DeviceTimeout", "CommunicationLost", "ProtocolError", "BadFrame", "DriveFault",
    "FollowingError", "MoveInterrupted",
    # the small protocols and the move logic (re-exported from their modules)
    "Movable", "Locatable", "Stoppable", "Readable", "Location", "Units", "UNITS", "MoveLogic",
    # axes
    "AxisState", "AxisStatus", "ServoAxis", "LinearAxis", "RotaryAxis",
    # encoder, camera
    "EncoderStatus", "EncoderReading", "PositionEncoder", "Frame", "CameraTiming", "Camera",
]

# --------------------------------------------------------------------------- errors


class DriverError(Exception):
    """Base of every error a driver raises; ``device`` names the device for messages."""

    def __init__(self, message: str, device: str = ""):
        self.device = device
        super().__init__(f"{device}: {message}" if device else message)


class DeviceTimeout(DriverError):
    """The device did not answer within the timeout (it may still be alive)."""


class CommunicationLost(DriverError):
    """The connection is down (refused, reset, port gone); the driver reconnects on the next call."""


class ProtocolError(DriverError):
    """A reply arrived but is not valid: bad checksum, bad framing, a Modbus exception response."""


class BadFrame(ProtocolError):
    """The camera delivered a frame that carries no image of the scene: black (no
    signal) or frozen (the previous image again under a new number). Retried like a
    garbled reply; persistent, it is a camera fault."""


class DriveFault(DriverError):
    """The drive reports a fault; ``code`` is the drive's fault code (see docs/register-map.md)."""

    def __init__(self, code: int, text: str, device: str = ""):
        self.code = int(code)
        self.text = text
        super().__init__(f"drive fault 0x{self.code:04X}: {text}", device)


class FollowingError(DriveFault):
    """The drive's position lagged its command by more than its limit (a jam, a crash, a stuck brake)."""


class MoveInterrupted(DriverError):
    """The drive came to rest short of the commanded target without a fault: a command
    was lost, or a stale one (a stop delayed on the link) overrode it. Re-issuing the
    absolute move is safe."""


# --------------------------------------------------------------------------- axes


class AxisState(enum.Enum):
    """Coarse state of an axis, derived from the status bits (for displays and the sequencer)."""

    DISABLED = "disabled"
    IDLE = "idle"
    MOVING = "moving"
    FAULT = "fault"


@dataclass(frozen=True)
class AxisStatus:
    """One snapshot of a servo drive: the status bits decoded, plus position and fault code.

    ``position`` is in the axis unit (mm for a linear axis, deg for a rotary one) and is
    what the drive's own motor encoder reports -- not the true carriage position.
    """

    ready: bool
    enabled: bool
    moving: bool
    in_position: bool
    homed: bool
    fault: bool
    following_error: bool
    estop: bool
    fault_code: int
    position: float
    velocity: float
    status_word: int = 0

    @property
    def state(self) -> AxisState:
        if self.fault or self.estop:
            return AxisState.FAULT
        if not self.enabled:
            return AxisState.DISABLED
        if self.moving:
            return AxisState.MOVING
        return AxisState.IDLE


class ServoAxis(abc.ABC):
    """Common face of a positioning axis; subclasses fix the unit (``units``: mm or deg).

    It satisfies the small protocols of :mod:`drivers.interfaces.protocols`:
    :class:`Movable` (``move_to``, ``units``), :class:`Locatable` (``setpoint``,
    ``locate``), :class:`Stoppable` (``stop``) and :class:`Readable` (``read``). A
    concrete axis implements the abstract methods and keeps ``_setpoint`` (the last
    target it commanded, None after a stop); the movable core -- :meth:`set`, move
    and wait with a timeout from the move's distance and profile -- is written here
    once, over :attr:`move_logic`, in the manner of ophyd-async's ``StandardMovable``.
    """

    #: a human name used in error messages ("Z", "C")
    name: str = "axis"
    #: the axis unit: "mm" (linear) or "deg" (rotary); velocities are units/s
    units: str = ""

    #: the velocity and acceleration the station may command (unit/s, unit/s^2): the
    #: integrator's limits for scanning, within the drive's own; None: not stated
    velocity_limit: float | None = None
    acceleration_limit: float | None = None
    #: the profile of a move that names none (unit/s, unit/s^2); None: the drive's own
    default_velocity: float | None = None
    default_acceleration: float | None = None
    #: how often ``wait_in_position`` asks the drive (s): on average the station sees
    #: the end of a move half a period late
    poll_s: float = 0.0
    #: the last target commanded (a concrete axis sets it; read it as ``setpoint``)
    _setpoint: float | None = None

    @property
    def unit(self) -> str:
        """The former name of :attr:`units` (kept for callers that still use it)."""
        return self.units

    @property
    def setpoint(self) -> float | None:
        """The last target commanded, in the axis unit: a move's target, 0 for homing;
        None before the first move and after a stop (the axis rests short of it by design)."""
        return self._setpoint

    @property
    def move_logic(self) -> MoveLogic:
        """This axis' move logic, from its present defaults and limits."""
        return MoveLogic(self.default_velocity, self.default_acceleration,
                         self.velocity_limit, self.acceleration_limit)

    @abc.abstractmethod
    async def connect(self) -> None:
        """Open the link and prepare the drive (watchdog, profile); idempotent."""

    @abc.abstractmethod
    async def close(self) -> None:
        """Stop background tasks and close the link; never raises."""

    @abc.abstractmethod
    async def enable(self, on: bool = True) -> None:
        """Power the motor (or remove power)."""

    @abc.abstractmethod
    async def move_to(self, position: float, velocity: float | None = None,
                      acceleration: float | None = None) -> None:
        """Start an absolute move (velocity and acceleration: the axis' defaults when
        None); returns once the drive accepted it (see ``wait_in_position``)."""

    @abc.abstractmethod
    async def stop(self) -> None:
        """Stop the current move (controlled deceleration)."""

    @abc.abstractmethod
    async def home(self) -> None:
        """Start the homing procedure (reference search)."""

    @abc.abstractmethod
    async def wait_in_position(self, timeout: float) -> AxisStatus:
        """Wait until the move is finished; raise DriveFault/FollowingError or DeviceTimeout."""

    @abc.abstractmethod
    async def read_position(self) -> float:
        """The drive's reported position in the axis unit."""

    @abc.abstractmethod
    async def status(self) -> AxisStatus:
        """One status snapshot."""

    @abc.abstractmethod
    async def reset_fault(self) -> None:
        """Acknowledge a drive fault (the cause must be gone for it to clear)."""

    # ------------------------------------------------------------------ the protocols' verbs

    async def read(self) -> AxisStatus:
        """:class:`Readable`: one status snapshot."""
        return await self.status()

    async def locate(self) -> Location:
        """:class:`Locatable`: the setpoint and the drive's reported position."""
        return Location(setpoint=self.setpoint, readback=await self.read_position())

    async def set(self, target: float, velocity: float | None = None, acceleration: float | None = None,
                  *, timeout: float | None = None) -> AxisStatus:
        """Move to ``target`` and wait until in position: the movable core.

        The move is checked first (:meth:`MoveLogic.check_move`); ``timeout`` (s) is by
        default the move logic's, from the distance (from the setpoint, or the reported
        position before the first move) and the profile."""
        logic = self.move_logic
        logic.check_move(target, velocity, acceleration)
        if timeout is None:
            start = self.setpoint
            if start is None:
                start = await self.read_position()
            timeout = logic.timeout_s(abs(float(target) - float(start)), velocity, acceleration)
        await self.move_to(target, velocity, acceleration)
        return await self.wait_in_position(timeout)

    async def __aenter__(self):
        await self.connect()
        return self

    async def __aexit__(self, *exc):
        await self.close()


class LinearAxis(ServoAxis):
    """A linear axis; positions in mm, velocities in mm/s."""

    units = "mm"


class RotaryAxis(ServoAxis):
    """A rotary axis; positions in deg, velocities in deg/s."""

    units = "deg"


# --------------------------------------------------------------------------- encoder


@dataclass(frozen=True)
class EncoderStatus:
    """Status bits of a grating encoder read head (see docs/encoder-protocol.md)."""

    referenced: bool
    signal_low: bool
    overspeed: bool
    hardware_error: bool
    raw: int = 0

    @property
    def ok(self) -> bool:
        return not (self.signal_low or self.overspeed or self.hardware_error)


@dataclass(frozen=True)
class EncoderReading:
    """A position read from the grating, with the host time (``time.monotonic``) it refers to."""

    position_mm: float
    timestamp: float
    status: EncoderStatus

    def __iter__(self):  # allows ``position_mm, timestamp, status = await enc.read()``
        return iter((self.position_mm, self.timestamp, self.status))


class PositionEncoder(abc.ABC):
    """An absolute/incremental position encoder read on request."""

    name: str = "encoder"

    @abc.abstractmethod
    async def connect(self) -> None: ...

    @abc.abstractmethod
    async def close(self) -> None: ...

    @abc.abstractmethod
    async def read(self) -> EncoderReading:
        """One reading; raise DeviceTimeout, ProtocolError or CommunicationLost."""

    async def __aenter__(self):
        await self.connect()
        return self

    async def __aexit__(self, *exc):
        await self.close()


# --------------------------------------------------------------------------- camera


@dataclass(frozen=True)
class Frame:
    """One grey image (uint8, shape (rows, cols)), the host time it was grabbed and its number."""

    image: np.ndarray = field(repr=False)
    timestamp: float
    sequence: int


@dataclass(frozen=True)
class CameraTiming:
    """What one frame costs in time on the sensor: ``exposure_s``, while which the
    camera must be still, and ``readout_s``, the sensor's transfer of the frame.  A
    frame on request costs both (``frame_s``); frames in a row overlap the readout of
    one with the exposure of the next where the sensor can."""

    exposure_s: float
    readout_s: float

    def __post_init__(self):
        for name in ("exposure_s", "readout_s"):
            v = getattr(self, name)
            if not (isinstance(v, (int, float)) and math.isfinite(v) and v >= 0):
                raise ValueError(f"camera {name} must be a number >= 0, not {v!r}")

    @property
    def frame_s(self) -> float:
        return self.exposure_s + self.readout_s


class Camera(abc.ABC):
    """A camera delivering grey frames on request."""

    name: str = "camera"
    #: the sensor's timing when known (a twin declares its sensor's; hardware from the
    #: config), else None
    timing: CameraTiming | None = None

    @abc.abstractmethod
    async def connect(self) -> None: ...

    @abc.abstractmethod
    async def close(self) -> None: ...

    @abc.abstractmethod
    async def grab(self) -> Frame:
        """The next frame; raise DeviceTimeout or CommunicationLost."""

    async def __aenter__(self):
        await self.connect()
        return self

    async def __aexit__(self, *exc):
        await self.close()
