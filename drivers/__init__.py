"""Abstract device interfaces and the real drivers (Modbus servo axes, serial grating encoder, V4L2 camera)."""
