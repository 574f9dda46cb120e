"""Fuzz targets: the station's readers of outside input, their seeds and strategies.

Each target (:func:`fuzz_targets`, :func:`modbus_target`) is fed mutations of valid
seed texts (:func:`mutated_text`) or scripted Modbus answers (:func:`modbus_scripts`);
an input passes (:func:`fuzz_one`) when it is accepted or fails with the target's
documented typed error carrying a message. ``tests/reliability/test_fuzz.py`` runs
them at a small count, ``station bench reliability`` at a large one (docs/reliability.md,
section 3).
"""

from __future__ import annotations

import asyncio
import contextlib
import signal
from dataclasses import dataclass
from typing import Any, Callable

from testkit.fakes import ByteTransport, FakeModbusClient
from testkit.session import PART


RECORDING_SEED = """# axis: Z
# kind: linear
time_s,run,direction,target,deviation,temperature_c,note
0.0,1,+1,0.0,0.1,20.0,a
1.0,1,+1,60.0,3.2,20.1,b
2.0,1,-1,60.0,1.1,20.2,
3.0,1,-1,0.0,-0.9,20.3,c
"""

AXIS_MODEL_SEED = """[axis]
name = "Z"
kind = "linear"

[baseline]
target = [0.0, 60.0, 120.0]
deviation = [0.0, 6.0, 18.0]

[noise]
sigma = 0.5

[[effects]]
name = "backlash"
reversal = 4.0
"""

#: tokens a mutation puts where a value was: the awkward cases of every text format
NASTY = ("", " ", "nan", "inf", "-inf", "1e999", "-0", "0x10", "1,5", "+", "-", "\"", "'", "[", "]", "{", "}",
         "=", "#", "\n", "\r\n", "\x00", "\ufeff", "é", "9" * 40, "-1", "0", "1e-320", "true", "[[x]]", ",,,")


@dataclass
class FuzzTarget:
    """One parser under fuzzing: valid seed texts to mutate, the call, and the typed
    errors its documentation allows (anything else is a crash)."""

    name: str
    seeds: Callable[[], list]
    call: Callable[[Any], Any]
    errors: tuple[type[BaseException], ...]
    binary: bool = False


def _table_seeds() -> list[str]:
    import numpy as np

    from station.compensation import files as f
    from station.compensation.table import CompensationTable

    pos = np.array([0.0, 30.0, 60.0, 90.0, 120.0])
    uni = CompensationTable(kind="linear", position=pos, error_mean=np.array([0.0, 1.5, 3.0, 2.0, -1.0]), axis="Z")
    bi = CompensationTable(kind="rotary", position=pos * 3, error_up=np.array([0.0, 1.0, 2.0, 1.0, 0.0]),
                           error_down=np.array([0.5, 1.5, 2.5, 1.5, 0.5]), axis="C")
    return [f.table_to_csv(uni), f.table_to_csv(bi), f.table_to_json(uni), f.table_to_json(bi),
            f.table_to_linuxcnc(uni, 0), f.table_to_linuxcnc(bi, 1)]


def _segment_seeds() -> list[str]:
    from station.compensation import files as f
    from station.compensation.segments import Segment, SegmentModel

    m = SegmentModel(segments=(Segment(0.0, 60.0, 0.05, 0.0), Segment(60.0, 120.0, -0.02, 4.2)))
    return [f.segments_to_csv(m), f.segments_to_json(m)]


def _model_seeds() -> list[str]:
    from importlib import resources

    paper = resources.files("sim").joinpath("scenarios/paper_model.toml")
    return [resources.files("station").joinpath("data/default_station.toml").read_text(),
            paper.read_text() if paper.is_file() else ""]


def _part_seeds() -> list[str]:
    from importlib import resources

    return [resources.files("station").joinpath(f"data/parts/{PART}.toml").read_text()]


def _model_call(text: str):
    import tomllib

    from station.kinematics.model import model_from_dict

    return model_from_dict(tomllib.loads(text), "<fuzz>")


def _axis_model_call(text: str):
    import tomllib

    from station.axis_model import axis_model_from_dict

    return axis_model_from_dict(tomllib.loads(text), "<fuzz>")


def _linuxcnc_call(text: str):
    from station.compensation.files import table_from_linuxcnc

    return table_from_linuxcnc(text, None, source="<fuzz>")


def _encoder_seeds() -> list[bytes]:
    from drivers.interfaces import encoder_protocol as ep

    return [ep.position_reply(842469, 1), ep.position_reply(-1234, 3), ep.identity_reply("GRT-005", "V1.3"),
            ep.error_reply(ep.EncoderErrorCode.UNKNOWN_COMMAND), b"\x00\xffnoise" + ep.position_reply(5, 1)]


def _find_frame_call(data: bytes):
    from drivers.encoder import find_frame

    return find_frame(data.rstrip(b"\r\n"))


def _encoder_driver_call(data: bytes):
    from drivers.encoder import SerialGratingEncoder

    enc = SerialGratingEncoder(transport=ByteTransport(data), timeout_s=0.01, retries=0)
    return asyncio.run(enc.read())


def _modbus_call(script: list):
    from drivers.modbus_axis import ModbusLinearAxis

    async def go():
        client = FakeModbusClient(script)
        ax = ModbusLinearAxis(lambda: client, name="Z", device_id=1, unit_per_count=1e-4, default_velocity=20.0,
                              default_acceleration=200.0, timeout_s=0.05, watchdog_timeout_ms=0)
        try:
            await ax.status()
            await ax.read_position()
            await ax.move_to(1.0)
            await ax.wait_in_position(timeout=0.05, poll_s=0.001)
        finally:
            await ax.close()

    return asyncio.run(go())


def fuzz_targets() -> list[FuzzTarget]:
    import tomllib

    from drivers.interfaces import DriverError
    from drivers.interfaces import encoder_protocol as ep
    from station.axis_model import AxisModelError
    from station.compensation import files as f
    from station.kinematics.model import ModelConfigError
    from station.kinematics.topology import TopologyError
    from station.parts.loader import PartSpecError, parse_part
    from station.recording import RecordingError, parse_recording

    return [
        FuzzTarget("recording", lambda: [RECORDING_SEED], lambda t: parse_recording(t, "<fuzz>"), (RecordingError,)),
        FuzzTarget("compensation table csv", lambda: _table_seeds()[:2], lambda t: f.table_from_csv(t, "<fuzz>"),
                   (f.FormatError,)),
        FuzzTarget("compensation segments csv", lambda: _segment_seeds()[:1],
                   lambda t: f.segments_from_csv(t, "<fuzz>"), (f.FormatError,)),
        FuzzTarget("compensation json", lambda: _table_seeds()[2:4] + _segment_seeds()[1:],
                   lambda t: f.from_json(t, "<fuzz>"), (f.FormatError,)),
        FuzzTarget("compensation linuxcnc", lambda: _table_seeds()[4:], _linuxcnc_call, (f.FormatError,)),
        FuzzTarget("part spec", _part_seeds, lambda t: parse_part(t, "<fuzz>"), (PartSpecError,)),
        FuzzTarget("axis model toml", lambda: [AXIS_MODEL_SEED], _axis_model_call,
                   (tomllib.TOMLDecodeError, AxisModelError)),
        FuzzTarget("station model toml", lambda: [t for t in _model_seeds() if t], _model_call,
                   (tomllib.TOMLDecodeError, ModelConfigError, TopologyError)),
        FuzzTarget("encoder find_frame", _encoder_seeds, _find_frame_call, (ep.FrameError,), binary=True),
        FuzzTarget("encoder driver", _encoder_seeds, _encoder_driver_call, (DriverError,), binary=True),
    ]


def modbus_target():
    from drivers.interfaces import DriverError

    return FuzzTarget("modbus responses", lambda: [], _modbus_call, (DriverError,))


def mutated_text(seed, binary: bool = False):
    """A hypothesis strategy: ``seed`` with random edits (cuts, inserts of random or nasty
    text, swapped lines, replaced characters), or entirely random text now and then."""
    from hypothesis import strategies as hs

    alphabet = hs.binary(max_size=30) if binary else hs.text(max_size=30)
    nasty = hs.sampled_from([n.encode("utf-8") for n in NASTY] if binary else list(NASTY))
    edit = hs.tuples(hs.sampled_from(["cut", "insert", "nasty", "dup", "swap"]), hs.floats(0, 1), hs.floats(0, 1),
                     hs.one_of(alphabet, nasty))

    def apply(edits):
        t = seed
        for op, a, b, piece in edits:
            n = len(t)
            i, j = sorted((int(a * n), int(b * n)))
            if op == "cut":
                t = t[:i] + t[j:]
            elif op == "insert":
                t = t[:i] + piece + t[i:]
            elif op == "nasty":
                t = t[:i] + piece + t[j if j - i < 12 else i + 1:]
            elif op == "dup":
                t = t[:j] + t[i:j] + t[j:]
            else:
                t = t[i:j] + t[:i] + t[j:]
        return t

    return hs.one_of(hs.lists(edit, min_size=1, max_size=6).map(apply), alphabet)


def modbus_scripts():
    from hypothesis import strategies as hs

    regs = hs.lists(hs.integers(0, 0xFFFF), max_size=10)
    item = hs.one_of(hs.tuples(hs.just("regs"), regs), hs.tuples(hs.just("stale"), regs),
                     hs.tuples(hs.just("error"), hs.none()),
                     hs.tuples(hs.just("none"), hs.none()), hs.tuples(hs.just("io"), hs.text(max_size=20)),
                     hs.tuples(hs.just("lost"), hs.text(max_size=20)))
    return hs.lists(item, max_size=12)


class Hang(Exception):
    """The call under fuzzing did not return within its time limit."""


@contextlib.contextmanager
def time_limit(seconds: float):
    """SIGALRM-bounded block (main thread only): a parser that loops raises :class:`Hang`."""
    def on_alarm(_sig, _frame):
        raise Hang(f"no answer within {seconds} s")

    old = signal.signal(signal.SIGALRM, on_alarm)
    signal.setitimer(signal.ITIMER_REAL, seconds)
    try:
        yield
    finally:
        signal.setitimer(signal.ITIMER_REAL, 0)
        signal.signal(signal.SIGALRM, old)


def fuzz_one(target: FuzzTarget, value, limit_s: float = 5.0) -> str | None:
    """Run one input: None when it parsed or failed with a documented error (which must
    carry a message), else what went wrong."""
    try:
        with time_limit(limit_s):
            target.call(value)
    except target.errors as exc:
        if not str(exc).strip():
            return f"{type(exc).__name__} without a message for {value!r:.200}"
        return None
    except Hang as exc:
        return f"hang: {exc} for {value!r:.200}"
    except Exception as exc:  # noqa: BLE001 - that is what fuzzing looks for
        return f"{type(exc).__name__}: {exc} for {value!r:.200}"
    return None
