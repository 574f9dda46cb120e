"""Hold the station's event loop at chosen moves of a plan, as synchronous work on it
(a compile, a solve) would: the drives' heartbeats pause, and their watchdog (1 s)
stops the axes for real in the twins. For the tests of what the station does after
such a stop (the axis check's repeat, the campaign's second inspection)."""

from __future__ import annotations

import time

from station.sequencer import messages as m


class LoopHold:
    """A message hook on ``engine``: before the n-th Move (counted from 1 over every
    plan the engine runs while it is on) for n in ``moves``, the loop sleeps
    ``seconds``. ``moves_seen``: how many Moves it has counted; ``remove()`` takes it off."""

    def __init__(self, engine, moves: set[int], seconds: float = 1.6) -> None:
        self.moves, self.seconds, self.moves_seen = set(moves), float(seconds), 0
        self.remove = engine.add_msg_hook(self._hook)

    def _hook(self, msg) -> None:
        if isinstance(msg, m.Move):
            self.moves_seen += 1
            if self.moves_seen in self.moves:
                time.sleep(self.seconds)
