"""The camera twin's renderer: synthetic endoscope frames with known ground truth.

``render`` draws bore-wall frames with compensating holes (and, from ``defects``,
pores, scratches, burrs and chips), ``target`` draws a calibration chessboard in
several poses, ``lens`` holds the Brown distortion model both use.  Everything is
pure numpy/OpenCV and seedable, so tests and benchmarks can regenerate the same frame
from a seed.
"""

from sim.camera.defects import DefectSpec, DefectTruth, random_defect_frame
from sim.camera.lens import BrownLens
from sim.camera.render import Frame, FrameParams, HoleSpec, HoleTruth, random_frame, render_frame

__all__ = ["BrownLens", "DefectSpec", "DefectTruth", "Frame", "FrameParams", "HoleSpec", "HoleTruth",
           "random_defect_frame", "random_frame", "render_frame"]
