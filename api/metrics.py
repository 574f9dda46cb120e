"""Prometheus metrics of the station, in a registry of the app's own.

A registry per app (not prometheus_client's global one) so that two apps in one
process (tests) do not clash over metric names.
"""

from __future__ import annotations

from prometheus_client import CollectorRegistry, Counter, Gauge, Histogram

#: inspection durations on the simulated station run a few seconds, on hardware a
#: minute or two: buckets cover both
DURATION_BUCKETS_S = (1, 2, 5, 10, 20, 30, 60, 90, 120, 180, 300, 600)


class Metrics:
    def __init__(self) -> None:
        self.registry = CollectorRegistry()
        self.inspections = Counter("station_inspections", "Inspections finished by this process, by outcome "
                                   "(pass, fail, aborted, faulted)", ["result"], registry=self.registry)
        self.duration = Histogram("station_inspection_duration_seconds", "Wall time of an inspection, "
                                  "job order to committed result", buckets=DURATION_BUCKETS_S, registry=self.registry)
        self.pass_rate = Gauge("station_pass_rate", "Passed / complete inspections in the store (0..1)",
                               registry=self.registry)
        self.driver_errors = Counter("station_driver_errors", "Driver errors seen by the engine: "
                                     "'retry' (transient, retried) and 'fault' (the engine faulted)", ["kind"],
                                     registry=self.registry)
        self.busy = Gauge("station_busy", "1 while an inspection, a master check or homing runs",
                          registry=self.registry)
        # the station's watch (docs/monitor.md): "station needs a check" and the charts' alarms
        self.needs_check = Gauge("station_needs_check", "1 while the station's control charts ask for a check "
                                 "on the certified master (an alarm since the last check in control), else 0",
                                 registry=self.registry)
        self.monitor_alarms = Counter("station_monitor_alarms", "Alarms the station's control charts raised in "
                                      "this process (production inspections and master checks)",
                                      registry=self.registry)
        for result in ("pass", "fail", "aborted", "faulted"):
            self.inspections.labels(result)  # present at 0 from the start, so rates work
        for kind in ("retry", "fault"):
            self.driver_errors.labels(kind)
