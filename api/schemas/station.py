"""The station: its status (``GET /station``, a command's answer, the SSE stream's first
event), its axes and its alarms."""

from __future__ import annotations

from pydantic import Field

from api.schemas.common import ClosedModel, IsoTime, Number, OpenModel


class Progress(OpenModel):
    """The running plan's progress, as the sequencer reports it."""

    done: int
    total: int
    text: str


class JobInfo(OpenModel):
    """The job the station runs (or ran last)."""

    kind: str = Field(description="inspection, check, calibration or home")
    inspection_id: str | None = Field(description="the inspection's id once it has one (inspections, checks)")
    running: bool


class GratingChart(OpenModel):
    """The grating-against-model chart (docs/monitor.md); um in units of the mean's standard error for `ewma`."""

    baseline_um: Number | None = Field(description="Phase I baseline; null until it is set")
    last_residual_um: Number | None = Field(description="the last inspection's grating minus the model's carriage")
    ewma: Number | None
    limit: Number | None
    arl0: Number | None = Field(description="in-control average run length, inspections")


class ScatterChart(OpenModel):
    """The frames' scatter chart (docs/monitor.md)."""

    reference_um: Number | None = Field(description="Phase I scatter (standard deviation); null until it is set")
    last_um: Number | None = Field(description="the last inspection's pooled scatter")
    ewma: Number | None
    limit: Number | None


class MasterChart(OpenModel):
    """The master checks' chart (docs/monitor.md)."""

    last_z: Number | None = Field(description="the last check's pooled z (null before the first check)")
    ewma: Number | None
    limit: Number | None
    arl0_checks: Number | None = Field(description="in-control average run length, checks")


class MonitorState(OpenModel):
    """The station's watch (``StationWatch.state()``)."""

    needs_check: bool = Field(description="the charts asked for a check on the master")
    reason: str | None = Field(description="the alarm's sentence; null when none")
    inspections_observed: int
    grating: GratingChart
    scatter: ScatterChart
    master: MasterChart
    alarms: int = Field(description="alarms the charts raised since the server started")


class StationStatus(OpenModel):
    """The station's state (``StationRuntime.station_status()``)."""

    state: str = Field(description="the sequencer's state: idle, homing, ready, running, paused, stopping, aborting, "
                                   "faulted or estopped")
    reason: str | None = Field(description="why it is in that state (a fault, an abort)")
    progress: Progress
    mode: str = Field(description="simulated or hardware")
    busy: bool = Field(description="a job is running: a job order or a check now gets 409")
    job: JobInfo | None
    needs_check: bool = Field(description="\"station needs a check\" (docs/api.md)")
    needs_check_reason: str | None
    monitor: MonitorState


class AxisReading(ClosedModel):
    """A drive as it reports itself; a drive that did not answer in time has only
    ``unit``, ``setpoint`` and ``error``."""

    unit: str = Field(description="mm (Z) or deg (C): the unit of setpoint, position and velocity")
    setpoint: Number | None = Field(description="the last target commanded; null after a stop")
    error: str | None = Field(description="why the drive could not be read; null when it was")
    position: Number | None = Field(default=None, description="as the drive's motor encoder reports it")
    velocity: Number | None = Field(default=None, description="per s")
    state: str | None = Field(default=None, description="disabled, idle, moving or fault")
    enabled: bool | None = None
    homed: bool | None = None
    moving: bool | None = None
    in_position: bool | None = None
    fault: bool | None = None
    fault_code: int | None = None
    estop: bool | None = Field(default=None, description="the drive's emergency stop input")


class GratingReading(ClosedModel):
    """The grating's reading of Z; when it did not answer, only ``unit`` and ``error``."""

    unit: str = Field(description="mm")
    error: str | None
    position: Number | None = Field(default=None, description="Z as the grating reads it, in unit")
    referenced: bool | None = Field(default=None, description="the reference mark was passed since power-on")
    ok: bool | None = Field(default=None, description="no signal, speed or hardware trouble")


class Axes(ClosedModel):
    """Z and C as their drives report them, and the grating's reading of Z."""

    Z: AxisReading
    C: AxisReading
    grating: GratingReading | None = Field(description="null when the station has no grating")


class Event(OpenModel):
    """An entry of the store's event log."""

    id: int
    inspection_id: str | None
    at: IsoTime
    kind: str = Field(description="fault, alarm, audit, command, ...")
    message: str
    station_id: str | None = Field(description="the station that logged it (null: older than station ids)")


class AlarmList(ClosedModel):
    """This station's faults and alarms, newest first."""

    items: list[Event]
