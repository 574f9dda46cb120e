"""Model proposals from the master's evidence: the named parameter, its size and sign by
the model's own sensitivity, the expected change, the book's states and the CLI's audit."""

from __future__ import annotations

import subprocess
import sys

import pytest

from station.kinematics.model import load_model
from station.monitor.proposals import (DATUM_TERM, SCALE_TERM, Change, ProposalBook, ProposalError, apply_changes,
                                       datum_proposal, datum_sensitivity, part_scale_ppm)
from station.store import Store

HOLES = {"hole_1": 71.03, "hole_2": 85.19}


def test_the_blocks_z_moves_the_point_on_the_part_one_for_one():
    # J carries the part: the part up by 1 um puts the detection point 1 um lower on it
    m = load_model()
    for z in HOLES.values():
        assert datum_sensitivity(m, z, 0.0) == pytest.approx(-1.0, abs=1e-6)


def test_a_datum_proposal_removes_the_mean_error_it_saw():
    m = load_model()
    p = datum_proposal(m, "v0", "why", {"hole_1.position": [8.2, 8.6], "hole_2.position": [8.3, 8.5]}, HOLES)
    (c,) = p.changes
    assert c.term == DATUM_TERM and c.delta == pytest.approx(8.4, abs=1e-6)
    assert p.expected_change_um == pytest.approx({"hole_1": -8.4, "hole_2": -8.4}, abs=1e-6)
    after = c.apply(m)
    assert after.static_errors["J"].z_um == pytest.approx(m.static_errors["J"].z_um + 8.4)
    assert after.static_errors["J"].x_um == m.static_errors["J"].x_um
    assert "ISO 230-1" in c.why and "spread 0.18 um over 4 values" in c.why
    with pytest.raises(ProposalError):
        datum_proposal(m, "v0", "why", {}, HOLES)
    # a check the knock fell into: one hole before it, one after: not one shift
    with pytest.raises(ProposalError, match="disagree"):
        datum_proposal(m, "v0", "why", {"hole_1.position": [0.3], "hole_2.position": [8.4]}, HOLES)
    with pytest.raises(ProposalError, match="only installation errors"):
        Change("motions.Z.EZZ", 1.0).apply(m)


def test_a_warm_part_is_reported_at_20_degC_and_the_datum_takes_the_rest():
    # a part 5 K warm (115 ppm) on a datum 1 um off: the holes read 1 + 0.115 a um long
    m = load_model()
    err = {f"{h}.position": [1.0 + 115.0 * 1e-3 * a] for h, a in HOLES.items()}
    p = datum_proposal(m, "v0", "why", err, HOLES, scale_ppm=115.0)
    scale, datum = p.changes
    assert scale.term == SCALE_TERM and scale.delta == pytest.approx(115.0)
    assert "5.0 K" in scale.why and "ISO 1" in scale.why
    assert datum.term == DATUM_TERM and datum.delta == pytest.approx(1.0, abs=1e-6)
    # every hole's reading comes back by its whole error; the evidence is kept as seen
    assert p.expected_change_um == pytest.approx({h: -err[f"{h}.position"][0] for h in HOLES}, abs=1e-6)
    assert p.evidence == err
    # the part's scale is not the machine's: the model is not touched by it
    assert scale.apply(m) is m and part_scale_ppm(p.changes) == pytest.approx(115.0)


def test_the_book_keeps_states_and_the_approved_changes_in_order(tmp_path):
    book = ProposalBook(tmp_path)
    m = load_model()
    a = book.add(datum_proposal(m, "v0", "first", {"hole_1.position": [2.0]}, HOLES))
    b = book.add(datum_proposal(m, "v0", "second", {"hole_1.position": [-1.0]}, HOLES))
    assert [p.id for p in book.list()] == [a.id, b.id]
    book.decide(a.id, True, "E. Engineer", "datum knocked, confirmed")
    book.decide(b.id, False, "E. Engineer")
    assert [c.delta for c in book.approved_changes()] == [pytest.approx(2.0)]
    assert book.get(a.id).decided_by == "E. Engineer" and book.get(b.id).state == "rejected"
    with pytest.raises(ProposalError, match="already approved"):
        book.decide(a.id, False, "someone")
    with pytest.raises(ProposalError, match="no proposal"):
        book.get("../../etc")
    applied = apply_changes(m, book.approved_changes(), "+1")
    assert applied.name == m.name + "+1" and applied.static_errors["J"].z_um == pytest.approx(m.static_errors["J"].z_um + 2.0)


def test_cli_decides_and_logs_the_decision(tmp_path):
    Store.open(data_dir=tmp_path).close()
    p = ProposalBook(tmp_path).add(datum_proposal(load_model(), "v0", "why", {"hole_1.position": [3.0]}, HOLES))

    def station(*args):
        return subprocess.run([sys.executable, "-m", "station.cli", "model", *args, "--data", str(tmp_path)],
                              capture_output=True, text=True, timeout=60)

    r = station("approve", p.id, "--who", "E. Engineer", "--note", "seen on the master")
    assert r.returncode == 0, r.stderr
    again = station("reject", p.id, "--who", "E. Engineer")
    assert again.returncode == 2 and "already approved" in again.stderr
    listed = station("proposals")
    assert p.id in listed.stdout and "approved by E. Engineer" in listed.stdout
    with Store(data_dir=tmp_path) as store:
        msgs = [e.message for e in store.events(kind="approval")]
    assert msgs == [f"model proposal {p.id} approved by E. Engineer (command line): seen on the master"]
