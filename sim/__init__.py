"""Simulated twins: the physical world, protocol-level twin servers, camera renderer, faults, scenarios."""
