"""``station bench drivers``: request rates of the real drivers through the twin servers.

The twins run in their own thread and event loop (``sim.twins.TwinsThread``), the
drivers in the bench's loop, so a round trip crosses a real TCP socket on 127.0.0.1
(Modbus) or a real pty (encoder) as it would on the station.  Reported as medians over
``repeats`` runs of ``requests`` requests each: a rate for the sequencer's budget
(status polls per second) and the matching median round-trip time.

The figures measure the software stack (pymodbus, pyserial, the twins), not a wire: a
real RS-485 or Ethernet drive adds its own cycle time.
"""

from __future__ import annotations

import asyncio
import statistics
import time

import typer

from station.cli.common import out_console, print_json


async def _rate(call, requests: int, repeats: int) -> dict[str, float]:
    rates = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        for _ in range(requests):
            await call()
        rates.append(requests / (time.perf_counter() - t0))
    median = statistics.median(rates)
    return {"per_s": median, "round_trip_ms": 1000.0 / median, "min_per_s": min(rates), "max_per_s": max(rates)}


async def _bench(requests: int, repeats: int) -> dict:
    from drivers.encoder import SerialGratingEncoder
    from drivers.interfaces import register_map as rm
    from drivers.modbus_axis import ModbusLinearAxis
    from sim.twins import TwinsThread

    runner = TwinsThread()
    try:
        eps = runner.start()
        z = eps["Z"]
        axis = ModbusLinearAxis.tcp(
            z["host"], z["port"], name="Z", device_id=z["device_id"], unit_per_count=z["unit_per_count"],
            default_velocity=20.0, default_acceleration=200.0,
            watchdog_timeout_ms=0,  # no heartbeat traffic competing with the measured requests
        )
        enc = SerialGratingEncoder(eps["encoder"]["path"], resolution_um=eps["encoder"]["resolution_um"])
        try:
            await axis.connect()
            await enc.connect()
            status = await _rate(axis.status, requests, repeats)
            write = await _rate(lambda: axis.write_registers(rm.WATCHDOG_COUNTER, [1]), requests, repeats)
            encoder = await _rate(enc.read, requests, repeats)
        finally:
            await axis.close()
            await enc.close()
    finally:
        runner.stop()
    return {
        "requests_per_repeat": requests,
        "repeats": repeats,
        "modbus_tcp_status_reads_per_s": status["per_s"],
        "modbus_tcp_status_read_round_trip_ms": status["round_trip_ms"],
        "modbus_tcp_register_writes_per_s": write["per_s"],
        "modbus_tcp_register_write_round_trip_ms": write["round_trip_ms"],
        "encoder_reads_per_s": encoder["per_s"],
        "encoder_read_round_trip_ms": encoder["round_trip_ms"],
        "spread": {"modbus_status": status, "modbus_write": write, "encoder": encoder},
    }


def run(requests: int = 300, repeats: int = 5) -> dict:
    return asyncio.run(_bench(requests, repeats))


def register(bench_app: typer.Typer) -> None:
    @bench_app.command("drivers")
    def drivers(
        requests: int = typer.Option(300, min=1, help="requests per repeat"),
        repeats: int = typer.Option(5, min=1, help="repeats; medians are reported"),
        json: bool = typer.Option(False, "--json", help="one JSON object on stdout"),
    ) -> None:
        """Modbus round trips and encoder reads per second through the twin servers."""
        with out_console.status("timing the drivers against the twins..."):
            result = run(requests, repeats)
        if json:
            print_json(result)
            return
        from rich.table import Table

        t = Table(title="Driver benchmark through the twins (medians)")
        t.add_column("request")
        t.add_column("rate", justify="right")
        t.add_column("round trip", justify="right")
        t.add_row("Modbus TCP status read (6 registers)", f"{result['modbus_tcp_status_reads_per_s']:,.0f} /s",
                  f"{result['modbus_tcp_status_read_round_trip_ms']:.2f} ms")
        t.add_row("Modbus TCP register write", f"{result['modbus_tcp_register_writes_per_s']:,.0f} /s",
                  f"{result['modbus_tcp_register_write_round_trip_ms']:.2f} ms")
        t.add_row("encoder ?P over pty", f"{result['encoder_reads_per_s']:,.0f} /s",
                  f"{result['encoder_read_round_trip_ms']:.2f} ms")
        out_console.print(t)
