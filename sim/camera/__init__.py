"""The camera twin's renderer: synthetic endoscope frames with known ground truth.

``render`` draws bore-wall frames with compensating holes, ``target`` draws a
calibration chessboard in several poses, ``lens`` holds the Brown distortion model
both use.  Everything is pure numpy/OpenCV and seedable, so tests and benchmarks can
regenerate the same frame from a seed.
"""

from sim.camera.lens import BrownLens
from sim.camera.render import Frame, FrameParams, HoleSpec, HoleTruth, random_frame, render_frame

__all__ = ["BrownLens", "Frame", "FrameParams", "HoleSpec", "HoleTruth", "random_frame", "render_frame"]
