"""An inspection as a stream of documents, in the manner of Bluesky's document model.

The inspection service judges; it does no side effects of its own. It publishes, in
this order, for every inspection:

    InspectionStart  (one: the id, the part, the serial, the traceability)
    FrameDocument    (one per measurement frame, live, as the plan takes it)
    HoleDocument     (one per spec hole: found and measured, or not found and why)
    SurfaceDocument  (one when the surface was scanned: its defects and picture)
    CheckDocument    (one per characteristic: measured, limits, U, conformance)
    InspectionStop   (one: the outcome; state, result, reason, findings, machine time)

An inspection that ends early (stopped, aborted, faulted) goes from its start straight
to its stop. Everything that records, shows or watches subscribes to the stream: the
store writer, the engine's event log and the scan log (``station.inspection.writers``),
the API's job tracking and live stream, the station's control charts, and in
simulation only the ground-truth annotator of the composition root.

A subscriber marked ``required`` is part of the result: if it fails, the document
goes no further and the publisher hears of it (the store writer: a result that is not
committed is not a result; the service then publishes the stop that really happened).
Any other subscriber's failure is kept in ``DocumentStream.errors`` and never stops
the inspection.
"""

from __future__ import annotations

import asyncio
import inspect
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any, Awaitable, Callable, ClassVar

if TYPE_CHECKING:
    from station.inspection.scan import FrameObservation, HoleResult
    from station.inspection.service import CharacteristicOutcome, InspectionOutcome
    from station.inspection.surface import SurfaceResult


@dataclass
class Document:
    kind: ClassVar[str] = "document"
    inspection_id: str


@dataclass
class InspectionStart(Document):
    kind: ClassVar[str] = "start"
    part_number: str = ""
    serial: str = ""
    order_id: str | None = None
    idempotency_key: str | None = None
    #: software, model and its fingerprint, camera scale, config, mode (the record's)
    traceability: dict[str, Any] = field(default_factory=dict)
    #: "production" (a part of the line) or "master" (a check of the station on its
    #: certified master): the control charts judge the two differently
    purpose: str = "production"


@dataclass
class FrameDocument(Document):
    kind: ClassVar[str] = "frame"
    hole: str = ""
    #: index of the frame within its hole's measurement frames (0-based)
    index: int = 0
    frame: "FrameObservation | None" = None


@dataclass
class HoleDocument(Document):
    kind: ClassVar[str] = "hole"
    hole: "HoleResult | None" = None


@dataclass
class SurfaceDocument(Document):
    kind: ClassVar[str] = "surface"
    surface: "SurfaceResult | None" = None


@dataclass
class CheckDocument(Document):
    kind: ClassVar[str] = "check"
    characteristic: "CharacteristicOutcome | None" = None


@dataclass
class InspectionStop(Document):
    kind: ClassVar[str] = "stop"
    outcome: "InspectionOutcome | None" = None
    #: the whole outcome's hole results with their crops (the record's images)
    holes: list = field(default_factory=list)


Subscriber = Callable[[Document], "Awaitable[None] | None"]


@dataclass
class SubscriberError:
    """A subscriber that failed on a document (kept, never raised for optional ones)."""

    subscriber: str
    document: str
    inspection_id: str
    error: str


class DocumentStream:
    """Subscribers in the order they subscribed; ``publish`` calls each with a document
    (coroutine functions awaited, plain functions called) and returns when all have it."""

    def __init__(self) -> None:
        self._subscribers: list[tuple[Subscriber, bool]] = []
        #: the optional subscribers' failures, newest last (bounded)
        self.errors: list[SubscriberError] = []

    def subscribe(self, fn: Subscriber, *, required: bool = False) -> Callable[[], None]:
        """Give ``fn`` every document from now on; returns a function that unsubscribes
        it. ``required``: its failure propagates to the publisher."""
        entry = (fn, required)
        self._subscribers.append(entry)

        def unsubscribe() -> None:
            if entry in self._subscribers:
                self._subscribers.remove(entry)

        return unsubscribe

    async def publish(self, doc: Document) -> None:
        """Give ``doc`` to every subscriber in turn. A required subscriber that fails
        ends the document there (the subscribers after it do not get it: a result the
        store did not take is not published as one) and its error propagates; the
        publisher then publishes what really happened."""
        for fn, required in list(self._subscribers):
            try:
                out = fn(doc)
                if inspect.isawaitable(out):
                    await out
            except asyncio.CancelledError:
                raise
            except Exception as exc:  # noqa: BLE001 - one subscriber must not silence the others
                if required:
                    raise
                self.errors.append(SubscriberError(getattr(fn, "__qualname__", repr(fn)), doc.kind,
                                                   doc.inspection_id, f"{type(exc).__name__}: {exc}"))
                del self.errors[:-100]
