"""Vision: find the compensating holes in an endoscope frame and measure them sub-pixel.

``measure_holes`` is the entry point; ``calibration`` turns chessboard views into
intrinsics, distortion and a mm-per-pixel scale.  Pixel convention: the centre of
pixel (0, 0) is at (0, 0), x right, y down (see docs/vision.md).
"""

from station.vision.calibration import CameraCalibration, calibrate
from station.vision.measure import HoleMeasurement, MeasureConfig, measure_holes

__all__ = ["CameraCalibration", "HoleMeasurement", "MeasureConfig", "calibrate", "measure_holes"]
