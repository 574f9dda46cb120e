"""Fixtures for protocol tests: twin servers on 127.0.0.1 / ptys, always torn down (finally)."""

from __future__ import annotations

import dataclasses

import pytest
import pytest_asyncio

from drivers.modbus_axis import ModbusLinearAxis, ModbusRotaryAxis
from sim.twins import Scenario, TwinStation, TwinsThread, load_scenario

#: moves run this much faster than real time, so a 10 mm move takes tens of ms
TEST_TIME_SCALE = 20.0


def fast_scenario(**station) -> Scenario:
    sc = load_scenario()
    return dataclasses.replace(sc, time_scale=station.get("time_scale", TEST_TIME_SCALE))


def make_axis(station: TwinStation, name: str, **kw):
    """A real driver pointed at the twin ``name`` of a started station."""
    ep = station.endpoints()[name]
    cls = ModbusLinearAxis if ep["kind"] == "linear" else ModbusRotaryAxis
    ax = station.scenario.axes[name]
    params = dict(
        name=name,
        device_id=ep["device_id"],
        unit_per_count=ep["unit_per_count"],
        default_velocity=ax.config.default_velocity,
        default_acceleration=ax.config.default_acceleration,
        timeout_s=0.3,
        watchdog_timeout_ms=1000,
        heartbeat_period_s=0.1,
    )
    params.update(kw)
    return cls.tcp(ep["host"], ep["port"], **params)


@pytest_asyncio.fixture
async def twins():
    """A started TwinStation in the test's event loop."""
    station = TwinStation(fast_scenario())
    await station.start()
    try:
        yield station
    finally:
        await station.stop()


@pytest_asyncio.fixture
async def z_axis(twins):
    axis = make_axis(twins, "Z")
    try:
        await axis.connect()
        yield axis
    finally:
        await axis.close()


@pytest.fixture
def twins_thread():
    """The twins in a background thread, for blocking (raw socket) clients."""
    runner = TwinsThread(TwinStation(fast_scenario()))
    try:
        runner.start()
        yield runner
    finally:
        runner.stop()
