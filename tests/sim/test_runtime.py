"""The composition root: a simulated station is the real drivers on the twins."""

from __future__ import annotations

import asyncio

import pytest

from station.runtime import ConfigError, build_station


def test_simulated_station_moves_and_the_grating_reads_the_true_carriage():
    station = build_station(time_scale=50.0)

    async def go():
        await station.connect()
        try:
            await station.z.enable(True)
            await station.z.home()
            await station.z.wait_in_position(timeout=30.0)
            await station.z.move_to(85.19)
            await station.z.wait_in_position(timeout=30.0)
            motor = await station.z.read_position()
            grating = (await station.encoder.read()).position_mm
            return motor, grating
        finally:
            await station.close()

    world = station.world
    motor, grating = asyncio.run(go())
    assert motor == pytest.approx(85.19, abs=2e-4)
    # the grating reads the world's carriage: the motor position plus the world's EZZ, this
    # approach's repeatability draw and the screw's (here negligible) warmth, to 0.05 um
    expected = 85.19 + world.z_offset_mm(85.19, +1, 0.0)
    assert grating == pytest.approx(expected, abs=1e-4)
    assert grating - motor > 0.010  # the screw's error at 85 mm is over 10 um
    # the station's belief is its own model, which the world does not follow: 0.8 um apart here
    assert station.model is not world.model and station.model.name != world.model.name
    ezz = [float(m.motions["Z"].z.evaluate([85.19], direction=[1])[0]) for m in (station.model, world.model)]
    assert abs(ezz[1] - ezz[0]) > 0.5
    assert station.twins is None  # close() stopped the twins


def test_config_errors_name_file_and_key(tmp_path):
    p = tmp_path / "station.toml"
    p.write_text('[station]\nmode = "warp"\n')
    with pytest.raises(ConfigError, match=r"station.toml: \[station\] mode must be"):
        build_station(p)
    p.write_text('[station]\nmode = "hardware"\n[hardware.Z]\nhost = "x"\n')
    with pytest.raises(ConfigError, match=r"needs a \[hardware.C\] table"):
        build_station(p)
    p.write_text('[station]\nmode = "hardware"\n[hardware.Z]\ntransport = "can"\n[hardware.C]\nhost = "h"\n')
    with pytest.raises(ConfigError, match=r"\[hardware.Z\] transport must be 'tcp' or 'rtu'"):
        build_station(p)
    p.write_text('[station]\nmode = "hardware"\n[hardware.Z]\nhost = "z"\n[hardware.C]\nhost = "c"\n'
                 '[hardware.camera]\ndevice = "x.avi"\nmm_per_px = 0.01\nresponse_gamma = 0.05\n')
    with pytest.raises(ConfigError, match=r"\[hardware.camera\] response_gamma: .*within"):
        build_station(p)
    p.write_text("[station\n")
    with pytest.raises(ConfigError, match="not valid TOML"):
        build_station(p)


def test_the_cameras_pixel_map_is_loaded_and_checked_against_its_frames(tmp_path):
    """``[hardware.camera] pixel_map``: the camera's flawed pixels (station vision
    pixel-map), loaded with the station and mended in every frame; a map of another frame
    size or a bad file is a configuration error naming both."""
    from station.vision.pixelmap import PixelMap

    PixelMap(1280, 1024, [(5, 7, "hot")], [(41, 0, 400, -12.0)], frames=16).save(tmp_path / "map.json")
    PixelMap(640, 480).save(tmp_path / "small.json")
    (tmp_path / "bad.json").write_text("{")
    head = '[station]\nmode = "hardware"\n[hardware.Z]\nhost = "z"\n[hardware.C]\nhost = "c"\n'
    cam = '[hardware.camera]\ndevice = "x.avi"\nmm_per_px = 0.01\n'
    p = tmp_path / "station.toml"
    p.write_text(head + cam + 'pixel_map = "map.json"\n')
    st = build_station(p)
    assert st.pixel_map.pixels == [(5, 7, "hot")] and st.pixel_map.columns[0][:3] == (41, 0, 400)
    p.write_text(head + cam + 'pixel_map = "small.json"\n')
    with pytest.raises(ConfigError, match=r"pixel_map: .*small.json is for 640 x 480 frames, the camera's are 1280 x"):
        build_station(p)
    p.write_text(head + cam + 'pixel_map = "bad.json"\n')
    with pytest.raises(ConfigError, match=r"\[hardware.camera\] pixel_map: .*bad.json: line 1"):
        build_station(p)
    p.write_text(head + cam)
    assert build_station(p).pixel_map is None


def test_a_worlds_camera_sensor_is_read_and_bad_keys_named(tmp_path):
    from sim.camera.sensor import SensorFlaws
    from sim.world import world_from_dict

    w = world_from_dict({"camera_sensor": {"seed": 3, "traps": 2}}, "s.toml")
    assert w.camera_sensor == SensorFlaws(seed=3, traps=2)
    assert world_from_dict({}, "s.toml").camera_sensor is None
    with pytest.raises(ValueError, match=r"s.toml: \[world.camera_sensor\] takes only .*not \['hot'\]"):
        world_from_dict({"camera_sensor": {"hot": 1}}, "s.toml")
    with pytest.raises(ValueError, match=r"s.toml: \[world.camera_sensor\]: sensor flaws: hot_share"):
        world_from_dict({"camera_sensor": {"hot_share": 0.5}}, "s.toml")


def test_example_hardware_config_builds_drivers_without_connecting(tmp_path):
    from pathlib import Path

    example = Path(__file__).resolve().parents[2] / "deploy" / "station.hardware.example.toml"
    # the example names the plant's model file; here the built-in one stands in for it
    text = "\n".join(l for l in example.read_text().splitlines() if not l.startswith("model ="))
    (tmp_path / "station.toml").write_text(text)
    st = build_station(tmp_path / "station.toml")
    assert st.mode == "hardware" and st.twins is None
    assert st.z.device_id == 1 and st.c.device_id == 2 and st.encoder is not None
