"""The OpenCV camera driver on a video file written by the test (MJPG in .avi)."""

from __future__ import annotations

import asyncio

import cv2
import numpy as np
import pytest

from drivers.camera import OpenCVCamera
from drivers.interfaces import CommunicationLost

LEVELS = (0, 60, 120, 180, 240)


@pytest.fixture
def video(tmp_path):
    path = tmp_path / "bore.avi"
    writer = cv2.VideoWriter(str(path), cv2.VideoWriter_fourcc(*"MJPG"), 10.0, (80, 60))
    assert writer.isOpened(), "opencv cannot write MJPG/avi here"
    try:
        for level in LEVELS:
            frame = np.full((60, 80, 3), level, np.uint8)
            frame[20:40, 30:50] = 255 - level  # a square, so frames are not flat
            writer.write(frame)
    finally:
        writer.release()
    return path


def test_frames_are_grey_numbered_and_in_order(video):
    async def run():
        cam = OpenCVCamera(video)
        try:
            await cam.connect()
            return [await cam.grab() for _ in LEVELS]
        finally:
            await cam.close()

    frames = asyncio.run(run())
    assert [f.sequence for f in frames] == [1, 2, 3, 4, 5]
    for f, level in zip(frames, LEVELS):
        assert f.image.shape == (60, 80) and f.image.dtype == np.uint8
        assert abs(int(np.median(f.image)) - level) <= 4  # JPEG loses a little
    assert all(b.timestamp >= a.timestamp for a, b in zip(frames, frames[1:]))


def test_a_colour_stream_is_grey_by_the_mean_of_its_channels(tmp_path):
    """A tinted stream (B, G, R at different levels): the driver's grey is the rounded
    mean of the decoded channels, the conversion the vision stage applies to colour
    files (drivers.interfaces.pixels.to_grey), not luminance weights."""
    path = tmp_path / "tinted.avi"
    writer = cv2.VideoWriter(str(path), cv2.VideoWriter_fourcc(*"MJPG"), 10.0, (80, 60))
    frame = np.zeros((60, 80, 3), np.uint8)
    frame[..., 0], frame[..., 1], frame[..., 2] = 200, 90, 30
    frame[20:40, 30:50] = (40, 160, 220)
    writer.write(frame)
    writer.release()
    cap = cv2.VideoCapture(str(path))
    ok, decoded = cap.read()
    cap.release()
    assert ok

    async def run():
        cam = OpenCVCamera(path)
        try:
            return await cam.grab()
        finally:
            await cam.close()

    grey = asyncio.run(run()).image
    expected = (decoded.astype(np.int32).sum(axis=2) + 1) // 3
    np.testing.assert_array_equal(grey, expected)
    # luminance weights would differ by tens of DN on this tint
    assert np.abs(cv2.cvtColor(decoded, cv2.COLOR_BGR2GRAY).astype(int) - expected).max() > 20


def test_end_of_file_is_typed_and_loop_rewinds(video):
    async def run(loop):
        cam = OpenCVCamera(video, loop=loop)
        try:
            out = [await cam.grab() for _ in LEVELS]
            out.append(await cam.grab())
            return out
        finally:
            await cam.close()

    with pytest.raises(CommunicationLost, match="end of video"):
        asyncio.run(run(False))
    frames = asyncio.run(run(True))
    assert abs(int(np.median(frames[-1].image)) - LEVELS[0]) <= 4


def test_missing_file_is_communication_lost(tmp_path):
    cam = OpenCVCamera(tmp_path / "none.avi")
    with pytest.raises(CommunicationLost):
        asyncio.run(cam.grab())


def test_device_sources_use_v4l2():
    assert OpenCVCamera(0).is_device and OpenCVCamera("/dev/video2").is_device
    assert not OpenCVCamera("replay.avi").is_device


def test_a_camera_that_encodes_with_a_gamma_delivers_frames_linear_in_light(video):
    """A camera whose pixels are full x (light / full)^gamma: the driver makes each frame
    linear again (``response_gamma``), so the vision stage models light; a gamma no camera
    has is refused."""
    async def run(gamma):
        cam = OpenCVCamera(video, response_gamma=gamma)
        try:
            await cam.connect()
            return [await cam.grab() for _ in LEVELS]
        finally:
            await cam.close()

    plain, linear = asyncio.run(run(1.0)), asyncio.run(run(0.5))
    for p, q in zip(plain, linear):
        expected = np.round(255.0 * (p.image / 255.0) ** 2.0)
        assert np.abs(q.image.astype(float) - expected).max() <= 0.5
    assert int(np.median(linear[2].image)) < int(np.median(plain[2].image)) - 40  # 120 -> 56
    with pytest.raises(ValueError, match="response_gamma"):
        OpenCVCamera(video, response_gamma=0.0)
