"""An inspection record as a QIF 3.0 results document (namespace ``http://qifstandards.org/xsd/qif3``).

A domain export: it reads only the record (:class:`station.store.InspectionRecord`)
and knows nothing of the REST API or the CLI, which both serve it
(``GET /api/v1/inspections/{id}/qif``, ``station results qif ID``).

Why QIF: the plant's quality systems read measurement results as QIF, the ANSI/ISO
standard that carries a characteristic's definition (tolerance), nominal, item and
measurement together, so a result keeps its meaning outside the station.

What goes where (element order follows QIFDocument.xsd, which is an ``xs:sequence``
everywhere, so order matters to a validator):

* ``StandardsDefinitions``: ISO 14405-1 (linear sizes), the standard the
  characteristics are toleranced by; ``Characteristics/FormalStandardId`` points at it.
* ``SoftwareDefinitions``: this software and its version, referenced from the
  results' traceability.
* ``FileUnits``: millimetres (the store's unit; QIF names the SI unit ``meter`` and
  converts with the factor 0.001).
* ``Product/PartSet/Part``: the part number.
* ``Characteristics``: per characteristic a definition (the tolerance as absolute
  limits, ``DefinedAsLimit`` true, exactly as stored with the result), a nominal
  (target value) and an item. A hole's diameter is a ``Diameter...`` characteristic;
  its axial position (distance of the hole's centre from the datum face along the
  bore axis) is a ``LinearCoordinate...`` characteristic in direction ``ZAXIS``.
* ``Results/MeasurementResultsSet/MeasurementResults``: one measurement per item
  with status PASS/FAIL and the measured value; its ``combinedUncertainty`` is the
  standard uncertainty u = U/2 (the store keeps the expanded U, k = 2) and
  ``meanError`` 0, because the GUM estimate is a result corrected for the known
  systematic effects (the schema asks for both attributes or neither). An
  unmeasured characteristic (hole not found) is FAIL without a value. Then the
  inspection status: PASS/FAIL when complete, SYSERROR when faulted, NOT_MEASURED
  when aborted or interrupted.
* ``Results/ActualComponentSets``: the inspected part's serial number.

Findings (an unexpected hole, an ambiguous identity, how the datum was set) are QIF
*noted events*. QIF 3.0 has no results element for "a feature the plan does not
expect": a measured feature or characteristic must point at a nominal of the plan,
``NonConformanceDesignator`` belongs to a characteristic measurement, and
``InspectionTraceability/Errors`` are failures of the measuring process. A
``NotedEvent`` is what the schema offers for "something that occurred during this
inspection, worth reporting", and its classification is a ``NotableEvent``: the
kind of event a plan asks to be reported (``Active`` true). So:

* ``PreInspectionTraceability/NotableEvents``: one ``NotableEvent`` per finding kind
  present (Description ``<kind>: <what it means>``). It has to live there: the
  schema's ``NotableEventIdKey`` admits only those as targets of a ``NotableEventId``.
  ``PreInspectionTraceability`` also requires ``FormalStandardId`` (ISO 14405-1).
* ``MeasurementResults/InspectionTraceability/NotedEvents``: one ``NotedEvent`` per
  finding in the record's order (Description ``<kind>: <message> (<where>)``,
  SequenceNumber 1, 2, ..., NotableEventId = its kind).
* ``MeasurementResults/InspectionTraceability/Attributes``: the same findings as
  typed values for a program: ``finding.<n>.kind`` / ``.subject`` (AttributeStr) and
  ``.axial_mm``, ``.angle_deg``, ``.diameter_mm``, ``.u_mm`` (AttributeD1; U is
  expanded, k = 2), each only where present; ``<n>`` is the NotedEvent's
  SequenceNumber. (An event element has nowhere to carry numbers of its own.)

Surface (issue 23): each surface criterion (``surface.<zone>.<kind>``, ``<hole>.burr``:
the largest defect of a kind, 0 when none) is a ``Length`` characteristic with its
limits 0 .. the spec's; each defect found is a ``NotedEvent`` of kind
``surface_defect`` (kind, size with U, place, the hole or zone, the criterion it breaks)
with its numbers as attributes ``defect.<n>.kind``, ``.hole``, ``.zone``, ``.rejects``
(AttributeStr) and ``.axial_mm``, ``.angle_deg``, ``.length_mm``, ``.width_mm``,
``.size_u_mm``, ``.position_u_mm`` (AttributeD1; U expanded, k = 2), ``<n>`` its
SequenceNumber after the findings'.

Machine time is left out: QIF 3.0 has no element for a cycle or machine time. The
wall-clock span is in ``InspectionStart``/``InspectionEnd``; the machine time (the
plan at the axes' real speeds, modelled under a twin) is a different quantity, and a
user attribute for it would be read only by programs told about it, which read the
REST API's ``machine_s`` and ``cycle`` anyway.

Ids: QIF ids are positive integers unique in the document (``QIFReferenceFull``
references point at them); ``idMax`` must be at least the largest id used.
"""

from __future__ import annotations

import uuid
import xml.etree.ElementTree as ET
from datetime import datetime
from typing import Any

from station.store.errors import InspectionStateError

QIF_NS = "http://qifstandards.org/xsd/qif3"
QIF_VERSION = "3.0.0"
#: a fixed namespace so a document's QPId is the same every time it is generated
#: for one inspection (a MES that fetches it twice sees one document, not two)
_QPID_NAMESPACE = uuid.UUID("6f1d3a52-1c55-4c8e-9a43-0b8f3f5e2d71")
#: inspection states with a verdict; others map to the QIF status beside them
_STATUS_OF_STATE = {"faulted": "SYSERROR", "aborted": "NOT_MEASURED", "interrupted": "NOT_MEASURED"}


class _Ids:
    """Hands out document ids 1, 2, 3 ... and remembers the largest (``idMax``)."""

    def __init__(self) -> None:
        self.last = 0

    def next(self) -> str:
        self.last += 1
        return str(self.last)


def _sub(parent: ET.Element, tag: str, text: Any = None, **attrs: str) -> ET.Element:
    el = ET.SubElement(parent, f"{{{QIF_NS}}}{tag}", {k: str(v) for k, v in attrs.items()})
    if text is not None:
        el.text = str(text)
    return el


def _decimal(v: float) -> str:
    """A float as an xs:decimal literal (no exponent, which xs:decimal does not allow)."""
    text = f"{v:.9f}".rstrip("0")
    return text + "0" if text.endswith(".") else text


def _kind(characteristic_id: str) -> str:
    """``hole_1.diameter`` -> ``diameter``; the part spec names them ``<hole>.<kind>``."""
    return characteristic_id.rsplit(".", 1)[-1]


#: the surface criteria's kinds (``station.parts.spec``): the largest defect's length
_SURFACE_KINDS = ("pore", "scratch", "burr", "chip")


def _prefix(characteristic_id: str) -> str:
    """The QIF characteristic type: a hole's diameter is a ``Diameter`` characteristic,
    its axial position a ``LinearCoordinate`` one, and a surface criterion (the largest
    pore, scratch, burr or chip, a length between 0 and its limit) a ``Length`` one."""
    kind = _kind(characteristic_id)
    if kind == "diameter":
        return "Diameter"
    return "Length" if kind in _SURFACE_KINDS else "LinearCoordinate"


def _surface_defects(record: Any) -> list[dict]:
    """The record's surface defects (its ``surface`` document), [] without one."""
    surface = getattr(record, "surface", None)
    return list((surface or {}).get("defects") or [])


#: a defect's numbers as typed attributes (QIF has no element for a surface defect)
_DEFECT_NUMBERS = ("axial_mm", "angle_deg", "length_mm", "width_mm", "size_u_mm", "position_u_mm")


def _defect_description(d: dict) -> str:
    where = d.get("hole") or d.get("zone")
    verdict = f", over the limit of {d['rejects']}" if d.get("rejects") else ""
    return (f"surface_defect: {d['kind']} {d['length_mm']:.3f} x {d['width_mm']:.3f} mm (U {d['size_u_mm']:.3f} mm) "
            f"at axial {d['axial_mm']:.3f} mm, angle {d['angle_deg']:.2f} deg"
            + (f" ({where})" if where else "") + verdict)


def _qif_datetime(t: datetime | None) -> str | None:
    return None if t is None else t.isoformat()


#: what each finding kind means (``station.store.models.FINDING_KINDS``), as the
#: NotableEvent's description; a kind not listed here is described by its name only
_FINDING_MEANING = {
    "unexpected_hole": "a hole in the scanned bands that no hole of the part spec claims "
                       "(a feature the inspection plan does not expect)",
    "ambiguous_identity": "two holes in one spec hole's search zone: which one is the spec hole is unknown",
    "datum": "how the part's angular datum on the table was set",
    "surface_defect": "a defect of the bore's inner surface (pore, scratch, burr or chip) found by the coverage "
                      "scan; its criteria are the Length characteristics",
}
#: a finding's optional numbers: (field, also the attribute's suffix; how the description says it)
_FINDING_NUMBERS = (("axial_mm", "axial {:.3f} mm"), ("angle_deg", "angle {:.2f} deg"),
                    ("diameter_mm", "diameter {:.3f} mm"), ("u_mm", "U {:.4f} mm (k=2)"))


def _finding_where(f: Any) -> str:
    """``axial 73.550 mm, angle 24.00 deg, diameter 0.800 mm, U 0.0021 mm (k=2)``:
    the numbers a finding has."""
    return ", ".join(fmt.format(getattr(f, name)) for name, fmt in _FINDING_NUMBERS
                     if getattr(f, name, None) is not None)


def _finding_description(f: Any) -> str:
    where = _finding_where(f)
    return f"{f.kind}: {f.message}" + (f" ({where})" if where else "")


def inspection_status(record: Any) -> str:
    """The QIF InspectionStatusEnum of an inspection record."""
    if record.state == "complete":
        return "PASS" if record.result == "pass" else "FAIL"
    return _STATUS_OF_STATE.get(record.state, "UNKNOWN")


def qif_document(record: Any, *, software_version: str = "") -> ET.Element:
    """The QIF results document of a finished inspection record
    (:class:`station.store.InspectionRecord`), as an element tree."""
    ET.register_namespace("", QIF_NS)
    ids = _Ids()
    root = ET.Element(f"{{{QIF_NS}}}QIFDocument", {"versionQIF": QIF_VERSION})
    _sub(root, "QPId", uuid.uuid5(_QPID_NAMESPACE, f"results/{record.id}"))

    standards = _sub(root, "StandardsDefinitions", n=1)
    std_id = ids.next()
    std = _sub(standards, "Standard", id=std_id)
    _sub(_sub(std, "Organization"), "StandardsOrganizationEnum", "ISO")
    _sub(std, "Designator", "14405-1")
    _sub(std, "Year", "2016")
    _sub(std, "Title", "GPS - Dimensional tolerancing - Part 1: Linear sizes")

    software_id = None
    if software_version:
        software_id = ids.next()
        sw = _sub(_sub(root, "SoftwareDefinitions", n=1), "Software", id=software_id)
        _sub(sw, "VendorName", "bore inspection station (open source)")
        _sub(sw, "ApplicationName", "station")
        _sub(sw, "Version", software_version)

    findings = list(getattr(record, "findings", ()))
    defects = _surface_defects(record)
    kind_ids: dict[str, str] = {}  # finding kind -> its NotableEvent's id
    if findings or defects:
        pre = _sub(root, "PreInspectionTraceability")
        kinds = list(dict.fromkeys(f.kind for f in findings))  # first-seen order
        if defects:
            kinds.append("surface_defect")
        notable = _sub(pre, "NotableEvents", n=len(kinds))
        for kind in kinds:
            kind_ids[kind] = ids.next()
            ev = _sub(notable, "NotableEvent", id=kind_ids[kind])
            meaning = _FINDING_MEANING.get(kind)
            _sub(ev, "Description", f"{kind}: {meaning}" if meaning else kind)
            _sub(ev, "Active", "true")
        _sub(pre, "FormalStandardId", std_id)

    units = _sub(_sub(root, "FileUnits"), "PrimaryUnits")
    lin = _sub(units, "LinearUnit")
    _sub(lin, "SIUnitName", "meter")  # the schema fixes the SI name; mm is meter x 0.001
    _sub(lin, "UnitName", "mm")
    _sub(_sub(lin, "UnitConversion"), "Factor", "0.001")

    product = _sub(root, "Product")
    part_id = ids.next()
    part = _sub(_sub(product, "PartSet", n=1), "Part", id=part_id)
    header = _sub(part, "Header")
    _sub(header, "Name", record.part_number)
    _sub(part, "ModelNumber", record.part_number)
    _sub(_sub(product, "RootPart"), "Id", part_id)

    chars = list(record.characteristics)
    items: list[tuple[Any, str]] = []  # (characteristic record, item id)
    if chars:
        block = _sub(root, "Characteristics")
        _sub(block, "FormalStandardId", std_id)
        defs = _sub(block, "CharacteristicDefinitions", n=len(chars))
        noms = _sub(block, "CharacteristicNominals", n=len(chars))
        its = _sub(block, "CharacteristicItems", n=len(chars))
        for c in chars:
            prefix = _prefix(c.characteristic_id)
            def_id, nom_id, item_id = ids.next(), ids.next(), ids.next()
            d = _sub(defs, f"{prefix}CharacteristicDefinition", id=def_id)
            _sub(d, "Name", c.characteristic_id)
            tol = _sub(d, "Tolerance")
            _sub(tol, "MaxValue", _decimal(c.upper_limit))
            _sub(tol, "MinValue", _decimal(c.lower_limit))
            _sub(tol, "DefinedAsLimit", "true")

            n = _sub(noms, f"{prefix}CharacteristicNominal", id=nom_id)
            _sub(n, "CharacteristicDefinitionId", def_id)
            _sub(n, "Name", c.characteristic_id)
            _sub(n, "TargetValue", _decimal(c.nominal))
            if prefix == "LinearCoordinate":
                # the axial position is measured along the bore axis, the station's Z
                _sub(n, "Direction", "ZAXIS")

            it = _sub(its, f"{prefix}CharacteristicItem", id=item_id)
            _sub(it, "Name", c.characteristic_id)
            _sub(it, "CharacteristicNominalId", nom_id)
            items.append((c, item_id))

    results = _sub(root, "Results")
    mrs = _sub(_sub(results, "MeasurementResultsSet", n=1), "MeasurementResults", id=ids.next())
    trace = _sub(mrs, "InspectionTraceability")
    if record.order_id:
        _sub(trace, "OrderNumber", record.order_id)
    _sub(trace, "ReportNumber", record.id)
    if findings or defects:
        noted = _sub(trace, "NotedEvents", n=len(findings) + len(defects))
        events = [(_finding_description(f), f.kind) for f in findings]
        events += [(_defect_description(d), "surface_defect") for d in defects]
        for seq, (text, kind) in enumerate(events, start=1):
            ev = _sub(noted, "NotedEvent", id=ids.next())
            _sub(ev, "Description", text)
            _sub(ev, "SequenceNumber", seq)
            _sub(ev, "NotableEventId", kind_ids[kind])
    if record.started_at is not None:
        _sub(trace, "InspectionStart", _qif_datetime(record.started_at))
    if record.finished_at is not None:
        _sub(trace, "InspectionEnd", _qif_datetime(record.finished_at))
    if software_id is not None:
        used = _sub(_sub(trace, "InspectionSoftwareItems"), "InspectionProgramExecutionSoftware", n=1)
        _sub(used, "Id", software_id)
    if findings or defects:
        attrs = []  # (element, name, value)
        for seq, f in enumerate(findings, start=1):
            attrs.append(("AttributeStr", f"finding.{seq}.kind", f.kind))
            if f.subject is not None:
                attrs.append(("AttributeStr", f"finding.{seq}.subject", f.subject))
            for name, _ in _FINDING_NUMBERS:
                v = getattr(f, name, None)
                if v is not None:
                    attrs.append(("AttributeD1", f"finding.{seq}.{name}", _decimal(v)))
        # a defect's attributes are numbered by its NotedEvent's SequenceNumber too
        for seq, d in enumerate(defects, start=len(findings) + 1):
            attrs.append(("AttributeStr", f"defect.{seq}.kind", d["kind"]))
            for name in ("hole", "zone", "rejects"):
                if d.get(name):
                    attrs.append(("AttributeStr", f"defect.{seq}.{name}", d[name]))
            for name in _DEFECT_NUMBERS:
                if d.get(name) is not None:
                    attrs.append(("AttributeD1", f"defect.{seq}.{name}", _decimal(d[name])))
        block = _sub(trace, "Attributes", n=len(attrs))
        for tag, name, value in attrs:
            _sub(block, tag, name=name, value=value)
    try:
        _sub(mrs, "ThisResultsInstanceQPId", uuid.UUID(record.id))
    except ValueError:
        pass  # not a UUID: QPId allows only UUIDs, and the id is in ReportNumber already
    if items:
        measurements = _sub(_sub(mrs, "MeasuredCharacteristics"), "CharacteristicMeasurements", n=len(items))
        for c, item_id in items:
            prefix = _prefix(c.characteristic_id)
            m = _sub(measurements, f"{prefix}CharacteristicMeasurement", id=ids.next())
            _sub(_sub(m, "Status"), "CharacteristicStatusEnum", "PASS" if c.passed else "FAIL")
            _sub(m, "CharacteristicItemId", item_id)
            if prefix == "LinearCoordinate":
                _sub(_sub(m, "TypeOfCoordinates"), "CoordinateEnum", "CYLINDRICAL_3D")
            if c.measured is not None:
                attrs = {}
                if c.uncertainty_k2 is not None:
                    attrs = {"combinedUncertainty": _decimal(c.uncertainty_k2 / 2.0), "meanError": "0"}
                _sub(m, "Value", _decimal(c.measured), **attrs)
    _sub(_sub(mrs, "InspectionStatus"), "InspectionStatusEnum", inspection_status(record))
    component_id = ids.next()
    ids_el = _sub(mrs, "ActualComponentIds", n=1)
    _sub(ids_el, "Id", component_id)

    comp_sets = _sub(results, "ActualComponentSets", n=1)
    comp = _sub(_sub(comp_sets, "ActualComponentSet", n=1), "ActualComponent", id=component_id)
    if record.serial:
        _sub(comp, "SerialNumber", record.serial)
    _sub(_sub(comp, "Status"), "InspectionStatusEnum", inspection_status(record))

    root.set("idMax", str(ids.last))
    return root


def qif_bytes(record: Any, *, software_version: str = "") -> bytes:
    """The document serialised as UTF-8 XML with a declaration."""
    tree = ET.ElementTree(qif_document(record, software_version=software_version))
    ET.indent(tree)
    return ET.tostring(tree.getroot(), encoding="utf-8", xml_declaration=True)


def finished_qif_bytes(record: Any, *, software_version: str = "") -> bytes:
    """:func:`qif_bytes` of a finished inspection (complete, aborted, faulted or
    interrupted); a running one has no results yet: :class:`InspectionStateError`
    (the REST route answers it with 409, the CLI with an error)."""
    if record.state == "running":
        raise InspectionStateError(f"inspection {record.id} is still running: no results yet")
    return qif_bytes(record, software_version=software_version)
