"""The servo drive twin: physics (``physics``, ``motion``) separate from its Modbus face (``modbus_face``)."""

from sim.servo.modbus_face import ModbusDriveTwin
from station.motion import TrapezoidalMove
from sim.servo.physics import DriveSnapshot, ServoAxisConfig, ServoAxisPhysics, zero_offset

__all__ = ["DriveSnapshot", "ModbusDriveTwin", "ServoAxisConfig", "ServoAxisPhysics", "TrapezoidalMove", "zero_offset"]
