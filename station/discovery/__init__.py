"""Mismatch discovery: what does the axis model miss in a recording?

Replay a recording through an axis model, estimate the noise floor from repeated
approaches, locate structure in the residual, choose effects from a library of
physics by a principled criterion, fit them jointly and report (contract:
``shared/spec/discovery.md``; method: ``docs/discovery.md``).
"""

from station.discovery.library import EXTRA_EFFECTS, LocalDefect
from station.discovery.engine import Discovery, discover, write_outputs

__all__ = ["Discovery", "discover", "write_outputs", "LocalDefect", "EXTRA_EFFECTS"]
