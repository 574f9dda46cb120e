"""The surface in QIF (issue 23): the criteria as Length characteristics with their
limits, each defect a noted event with its numbers as attributes, the document valid
against the official QIF 3.0 schemas (the ``qif_schema`` fixture)."""

from __future__ import annotations

import xml.etree.ElementTree as ET

from station.exports.qif import QIF_NS, finished_qif_bytes
from station.inspection.service import judge_surface
from station.parts import load_part
from station.store import Measurement, Store, Traceability
from tests.surface_cases import synthetic_surface

NS = {"q": QIF_NS}
PART = "ZDZG-22.2-12.3851"


def test_surface_criteria_and_defects_go_into_a_valid_qif_document(tmp_path, qif_schema):
    spec = load_part(PART)
    surface = synthetic_surface()
    chars = judge_surface(spec, surface)
    store = Store.open(data_dir=tmp_path)
    try:
        iid = store.begin_inspection(PART, serial="SN-QIF-SURF", traceability=Traceability())
        ms = [Measurement.of(spec.characteristic(f"{h}.{k}"), v, passed=True, uncertainty_k2=0.002)
              for h, k, v in (("hole_1", "diameter", 0.70), ("hole_1", "position", 71.03),
                              ("hole_2", "diameter", 0.70), ("hole_2", "position", 85.19))]
        by_id = {c.id: c for c in spec.surface_characteristics()}
        ms += [Measurement.of(by_id[c.id], c.measured, passed=c.passed, uncertainty_k2=c.uncertainty_k2)
               for c in chars]
        store.finish(iid, "complete", "fail", "surface", measurements=ms, surface=surface.to_json())
        record = store.get(iid)
    finally:
        store.close()
    doc = finished_qif_bytes(record, software_version="test")
    qif_schema.validate(doc)
    root = ET.fromstring(doc)
    lengths = root.findall(".//q:CharacteristicDefinitions/q:LengthCharacteristicDefinition", NS)
    assert sorted(d.findtext("q:Name", namespaces=NS) for d in lengths) == sorted(c.id for c in chars)
    for d in lengths:
        c = by_id[d.findtext("q:Name", namespaces=NS)]
        assert float(d.findtext("q:Tolerance/q:MaxValue", namespaces=NS)) == c.upper_limit
        assert float(d.findtext("q:Tolerance/q:MinValue", namespaces=NS)) == 0.0
    # the holes keep their own types
    assert len(root.findall(".//q:CharacteristicDefinitions/q:DiameterCharacteristicDefinition", NS)) == 2
    assert len(root.findall(".//q:CharacteristicDefinitions/q:LinearCoordinateCharacteristicDefinition", NS)) == 2
    measured = root.findall(".//q:CharacteristicMeasurements/q:LengthCharacteristicMeasurement", NS)
    assert len(measured) == len(chars)
    fails = [m for m in measured if m.findtext("q:Status/q:CharacteristicStatusEnum", namespaces=NS) == "FAIL"]
    assert len(fails) == sum(not c.passed for c in chars) > 0
    events = root.findall(".//q:InspectionTraceability/q:NotedEvents/q:NotedEvent", NS)
    texts = [e.findtext("q:Description", namespaces=NS) for e in events]
    assert sum(t.startswith("surface_defect: ") for t in texts) == len(surface.defects)
    attrs = {a.get("name"): a.get("value") for a in root.findall(".//q:InspectionTraceability/q:Attributes/*", NS)}
    for n, d in enumerate(surface.defects, start=1):
        assert attrs[f"defect.{n}.kind"] == d.kind
        assert abs(float(attrs[f"defect.{n}.axial_mm"]) - d.axial_mm) < 1e-6
        assert abs(float(attrs[f"defect.{n}.length_mm"]) - d.length_mm) < 1e-6
