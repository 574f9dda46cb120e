"""The grating encoder twin (serial protocol on a pty)."""

from sim.encoder.twin import SerialEncoderTwin

__all__ = ["SerialEncoderTwin"]
