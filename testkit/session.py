"""An inspection session on the twins, living in an event loop of its own.

The fault matrix's point is that the *same* session recovers from one fault after
another, cell after cell, without a restart; pytest's test functions and the bench's
loop are synchronous, so the session is opened in a :class:`station.loopthread.LoopThread`
and every cell is run there with :meth:`SessionThread.run`.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any, Callable

from station.loopthread import LoopThread

#: the part every reliability run inspects: the built-in sample part (docs/part-specs.md)
PART = "ZDZG-22.2-12.3851"
#: motion runs this much faster than real time in the matrix and the crash trials
#: (timeouts stay real: they are what the faults test)
TIME_SCALE = 100.0
#: measurement frames per hole (the station's default is 5): three still give a mean and a
#: scatter, at three fifths of the frames
FRAMES_PER_HOLE = 3
#: how long opening a session may take (store migration, twins, renderer worker) on a
#: loaded two-core PC
OPEN_TIMEOUT_S = 60.0
#: how long closing it may take (drives, twins, the store)
CLOSE_TIMEOUT_S = 30.0


def use_small_frame(session) -> None:
    """Render 320 x 256 frames at the same 10 um/px (``sim.camera.twin.small_optics``):
    a quarter of the standard frame's pixels, the same measurement scale, so the
    matrix's many inspections cost less without changing what is measured."""
    from sim.camera.twin import small_optics

    optics = small_optics()
    session.station.camera.optics = optics
    session.station.frame_size_px = (optics.params.width_px, optics.params.height_px)


class SessionThread:
    """An inspection session in a background thread's loop, so that several tests (or
    bench cells) can share it. ``run(fn)`` runs ``await fn(session)`` there."""

    def __init__(self, data_dir: str | Path, *, time_scale: float = TIME_SCALE,
                 frames_per_hole: int = FRAMES_PER_HOLE, small_frame: bool = True):
        self.data_dir = Path(data_dir)
        self.time_scale = time_scale
        self.frames_per_hole = frames_per_hole
        self.small_frame = small_frame
        self.session = None
        self._runner = LoopThread("session")

    def _open(self):
        from station.inspection.scan import ScanSettings
        from station.runtime import open_session

        return open_session(time_scale=self.time_scale, data_dir=self.data_dir,
                            settings=ScanSettings(frames_per_hole=self.frames_per_hole))

    def _setup(self, session) -> None:
        if self.small_frame:
            use_small_frame(session)

    def start(self, timeout: float = OPEN_TIMEOUT_S) -> "SessionThread":
        """Open the session (at most ``timeout`` s); an error opening it is raised here."""
        self._runner.start()
        try:
            self.session = self._runner.enter(self._open, self._setup, timeout=timeout)
        except TimeoutError:
            self._runner.stop(CLOSE_TIMEOUT_S)
            raise TimeoutError("the session did not open in time") from None
        except BaseException:
            self._runner.stop(CLOSE_TIMEOUT_S)
            raise
        return self

    def run(self, fn: Callable[[Any], Any], timeout: float = 120.0) -> Any:
        """``await fn(session)`` on the session's loop; after ``timeout`` s it is
        cancelled and ``TimeoutError`` raised."""
        if self.session is None:
            raise RuntimeError("the session is not open")
        return self._runner.run(fn(self.session), timeout)

    def close(self) -> None:
        """Close the session on its loop and end the thread."""
        self._runner.stop(CLOSE_TIMEOUT_S)
        self.session = None

    def __enter__(self):
        return self.start()

    def __exit__(self, *exc):
        self.close()
