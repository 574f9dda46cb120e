"""Compensation tables: interpolation, build from a recording, file round trips, validation, CLI."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest
from typer.testing import CliRunner

from station.cli import app
from station.compensation import (
    CompensationTable,
    FormatError,
    SegmentModel,
    TableError,
    check,
    read_compensation,
    segments_from_csv,
    segments_to_table,
    table_from_csv,
    table_from_linuxcnc,
    table_from_recording,
    table_to_csv,
    table_to_json,
    table_to_linuxcnc,
    table_to_segments,
)
from station.compensation.files import detect_linuxcnc_type, from_json
from station.recording import parse_recording

runner = CliRunner()


def one_line(text: str) -> str:
    return " ".join(text.split())  # rich wraps long lines


# ---------------------------------------------------------------- interpolation

def test_linear_interpolation_and_flat_ends():
    t = CompensationTable.bidirectional("linear", [0.0, 10.0, 20.0], [0.0, 4.0, 2.0], [-2.0, 2.0, 0.0])
    np.testing.assert_allclose(t.error_at([5.0, 15.0], +1), [2.0, 3.0])
    np.testing.assert_allclose(t.error_at([5.0, 15.0], -1), [0.0, 1.0])
    np.testing.assert_allclose(t.error_at([5.0], 0), [1.0])  # mean of both directions
    # held flat outside the table
    np.testing.assert_allclose(t.error_at([-100.0, 500.0], +1), [0.0, 2.0])
    # the correction is the negative of the error
    np.testing.assert_allclose(t.correction_at([5.0, 15.0], +1), [-2.0, -3.0])
    # direction per point
    np.testing.assert_allclose(t.error_at([5.0, 5.0], np.array([1, -1])), [2.0, 0.0])


def test_rotary_interpolation_wraps_modulo_360():
    t = CompensationTable.averaged("rotary", [0.0, 90.0, 180.0, 270.0], [10.0, 20.0, 30.0, 40.0], backlash=4.0)
    # between 270 and 360 (= 0 again): 40 -> 10
    np.testing.assert_allclose(t.error_at([315.0, -45.0, 675.0]), [25.0, 25.0, 25.0])
    np.testing.assert_allclose(t.error_at([360.0, 720.0, -360.0]), [10.0, 10.0, 10.0])
    np.testing.assert_allclose(t.error_at([45.0]), [15.0])
    # averaged + backlash: ±b/2 by direction
    np.testing.assert_allclose(t.error_at([45.0], +1), [17.0])
    np.testing.assert_allclose(t.error_at([45.0], -1), [13.0])
    # a linear axis does NOT wrap: 315 is beyond the end, held at 40
    lin = CompensationTable.averaged("linear", [0.0, 90.0, 180.0, 270.0], [10.0, 20.0, 30.0, 40.0])
    np.testing.assert_allclose(lin.error_at([315.0]), [40.0])


def test_rotary_table_closed_at_360_does_not_add_a_second_wrap():
    t = CompensationTable.averaged("rotary", [0.0, 180.0, 360.0], [0.0, 10.0, 0.0])
    np.testing.assert_allclose(t.error_at([270.0, 90.0, 450.0]), [5.0, 5.0, 5.0])


def test_invalid_table_refuses_to_interpolate():
    t = CompensationTable.averaged("linear", [0.0, 20.0, 10.0], [0.0, 1.0, 2.0])
    with pytest.raises(TableError, match="20"):
        t.error_at(5.0)


# ---------------------------------------------------------------- build from a recording

def synthetic_recording(reversal_um: float = 4.0) -> str:
    """Error 0.05 um/mm · x, up reads +reversal/2, down −reversal/2; uneven reversal per target."""
    extra = {0.0: 0.0, 50.0: 1.0, 100.0: -1.0}  # B_i = 4, 6, 2 -> B̄ = 4
    lines = ["# kind: linear", "# axis: Z", "time_s,run,direction,target,deviation"]
    t = 0
    for run in (1, 2):
        for d, targets in ((+1, (0.0, 50.0, 100.0)), (-1, (100.0, 50.0, 0.0))):
            for x in targets:
                noise = 0.1 if run == 1 else -0.1
                dev = 0.05 * x + d * (reversal_um / 2 + extra[x]) + noise
                lines.append(f"{t},{run},{d:+d},{x},{dev!r}")
                t += 1
    return "\n".join(lines) + "\n"


def test_build_bidirectional_and_averaged_from_recording():
    rec = parse_recording(synthetic_recording(), "rec.csv")
    bi = table_from_recording(rec, "bidirectional")
    assert bi.mode == "bidirectional" and bi.axis == "Z"
    np.testing.assert_allclose(bi.position, [0.0, 50.0, 100.0])
    # x̄↑ = 0.05x + 2 + extra, x̄↓ = 0.05x − 2 − extra (noise ±0.1 averages out)
    np.testing.assert_allclose(bi.error_up, [2.0, 5.5, 6.0], atol=1e-12)
    np.testing.assert_allclose(bi.error_down, [-2.0, -0.5, 4.0], atol=1e-12)
    av = table_from_recording(rec, "averaged")
    assert av.mode == "averaged"
    np.testing.assert_allclose(av.error_mean, [0.0, 2.5, 5.0], atol=1e-12)
    assert av.backlash == pytest.approx(4.0)  # B̄ = mean(4, 6, 2)
    # bidirectional reproduces the per-target means exactly; averaged only up to B_i − B̄
    np.testing.assert_allclose(bi.error_at(50.0, +1), 5.5)
    np.testing.assert_allclose(av.error_at(50.0, +1), 4.5)
    np.testing.assert_allclose(av.error_at(0.0, -1), -2.0)


def test_build_refuses_a_target_without_both_directions():
    lines = [ln for ln in synthetic_recording().splitlines() if ",-1,50.0," not in ln]
    rec = parse_recording("\n".join(lines) + "\n")
    with pytest.raises(ValueError, match="no down .* at 50"):
        table_from_recording(rec)


# ---------------------------------------------------------------- round trips

def awkward_table(kind: str) -> CompensationTable:
    """Values that do not survive a naive /1000 or /3600 and back."""
    pos = [0.0, 12.5, 33.3, 47.1, 100.0] if kind == "linear" else [0.0, 45.0, 90.5, 200.25, 359.0]
    up = [0.1, 3.1, -7.3, 1 / 3, 12.345678901234]
    down = [-0.7, 2.9999999, -8.123, 2 / 3, -1e-5]
    return CompensationTable.bidirectional(kind, pos, up, down)


@pytest.mark.parametrize("kind", ["linear", "rotary"])
@pytest.mark.parametrize("comp_type", [0, 1])
def test_linuxcnc_round_trip_is_exact(kind, comp_type, tmp_path):
    table = awkward_table(kind)
    text = table_to_linuxcnc(table, comp_type)
    back = table_from_linuxcnc(text, comp_type, kind=kind)
    assert back.equals(table)
    # and through the file reader with the type detected from the numbers
    p = tmp_path / "z.comp"
    p.write_text(text)
    assert detect_linuxcnc_type(text) == comp_type
    assert read_compensation(p, kind=kind).equals(table)


def test_linuxcnc_columns_mean_what_linuxcnc_says():
    # error +3 um going up, −1 um going down at nominal 10 mm
    table = CompensationTable.bidirectional("linear", [0.0, 10.0], [0.0, 3.0], [0.0, -1.0])
    type0 = table_to_linuxcnc(table, 0).splitlines()[1].split()
    type1 = table_to_linuxcnc(table, 1).splitlines()[1].split()
    # type 0: actual positions (nominal + error), in mm
    assert [float(v) for v in type0] == [10.0, 10.003, 9.999]
    # type 1: trims LinuxCNC adds to the command = correction = −error, in mm
    assert [float(v) for v in type1] == [10.0, -0.003, 0.001]
    # LinuxCNC's loader turns type 0 into trims as nominal − actual: the same numbers
    assert 10.0 - float(type0[1]) == pytest.approx(float(type1[1]))


def test_averaged_table_to_linuxcnc_splits_backlash():
    table = CompensationTable.averaged("linear", [0.0, 10.0], [1.0, 2.0], backlash=4.0)
    back = table_from_linuxcnc(table_to_linuxcnc(table, 1), 1)
    np.testing.assert_allclose(back.error_up, [3.0, 4.0])
    np.testing.assert_allclose(back.error_down, [-1.0, 0.0])


@pytest.mark.parametrize("make", [
    lambda: awkward_table("linear"),
    lambda: CompensationTable.averaged("rotary", [0.0, 120.0, 240.0], [1 / 3, -2.5, 7.0], backlash=0.1, axis="C"),
])
def test_csv_and_json_round_trips_are_exact(make, tmp_path):
    table = make()
    assert table_from_csv(table_to_csv(table)).equals(table)
    assert from_json(table_to_json(table)).equals(table)
    for name in ("t.csv", "t.json"):
        p = tmp_path / name
        p.write_text(table_to_csv(table) if name.endswith("csv") else table_to_json(table))
        assert read_compensation(p).equals(table)


def test_linuxcnc_reader_refuses_what_linuxcnc_would_silently_drop():
    with pytest.raises(FormatError, match="line 1.*no compensation at all"):
        table_from_linuxcnc("# header\n0 0 0\n10 10.001 9.999\n", 0)
    with pytest.raises(FormatError, match="line 2.*1 line"):
        table_from_linuxcnc("0 0 0\n\n10 10.001 9.999\n", 0)
    with pytest.raises(FormatError, match="three numbers per line"):
        table_from_linuxcnc("0 0.001\n10 0.002\n", 1)


# ---------------------------------------------------------------- segments

EQ16_COLUMNS = ("x_from", "x_to", "slope", "intercept")


def test_eq16_check_names_every_junction_jump(paper_data):
    path = paper_data / "eq16-compensation.csv"
    model = read_compensation(path)
    assert isinstance(model, SegmentModel) and len(model) == 10
    problems = check(model)
    jumps = [p for p in problems if p.code == "discontinuity"]
    # expected jumps computed here from the file's numbers, segment by segment:
    # at each junction x, jump = (slope_r·x + intercept_r) − (slope_l·x + intercept_l)
    rows = sorted((tuple(float(v) for v in ln.split(",")) for ln in path.read_text().splitlines()
                   if ln and not ln.startswith("#") and not ln.startswith("x_from")))
    expected = {}
    for (a0, a1, am, ac), (b0, b1, bm, bc) in zip(rows[:-1], rows[1:]):
        assert a1 == b0  # the segments tile the range: no gaps, only jumps
        expected[a1] = (bm * a1 + bc) - (am * a1 + ac)
    # by hand (to 4 decimals) from the printed coefficients:
    #   x=-20: (-0.0391·-20 − 3.5370) − (−0.7856·−20 + 11.7939) = −2.7550 − 27.5059 = −30.2609
    #   x=-15: −2.8776 − (−2.9505) = +0.0729      x=-10: 7.0509 − (−3.1891) = +10.2400
    #   x=-5:  −7.7190 − 1.6194 = −9.3384          x=0:   −11.3321 − (−8.7930) = −2.5391
    #   x=5:   −34.0488 − (−11.5276) = −22.5212    x=10:  14.2309 − (−39.7768) = +54.0077
    #   x=15:  −22.1996 − 13.5724 = −35.7720       x=20:  7.6289 − (−22.7841) = +30.4130
    by_hand = {-20: -30.2609, -15: 0.0729, -10: 10.2400, -5: -9.3384, 0: -2.5391,
               5: -22.5212, 10: 54.0077, 15: -35.7720, 20: 30.4130}
    assert sorted(expected) == sorted(by_hand)
    for x, jump in by_hand.items():
        assert expected[x] == pytest.approx(jump, abs=5e-5)
    assert len(jumps) == 9
    for p in jumps:
        assert p.size == pytest.approx(by_hand[round(p.position)], abs=5e-5)
        assert p.line is not None
        assert f"x = {round(p.position):g}" in p.message
    assert any(p.code == "order" and "descending" in p.message for p in problems)
    # it cannot become a table
    with pytest.raises(TableError, match="jump"):
        segments_to_table(model)


def test_eq16_cli_check_lists_every_jump_and_fails(paper_data):
    result = runner.invoke(app, ["compensation", "check", str(paper_data / "eq16-compensation.csv")])
    assert result.exit_code == 1
    text = result.stdout
    for x, jump in ((-20, "-30.2609"), (-15, "+0.0729"), (-10, "+10.2400"), (-5, "-9.3384"), (0, "-2.5391"),
                    (5, "-22.5212"), (10, "+54.0077"), (15, "-35.7720"), (20, "+30.4130")):
        assert f"jump of {jump} at x = {x}" in text
    assert "descending" in text


def test_segments_gaps_overlaps_and_continuous_model():
    text = ("x_from,x_to,slope,intercept\n"
            "0,10,1,0\n"      # y(10) = 10
            "10,20,0,10\n"    # meets: continuous
            "21,30,0,10\n"    # gap of 1 at 20..21
            "29,40,0,10\n")   # overlap of 1 on 29..30
    problems = check(segments_from_csv(text, "s.csv"))
    codes = {(p.code, p.position, p.size) for p in problems}
    assert ("gap", 20.0, 1.0) in codes
    assert ("overlap", 29.0, 1.0) in codes
    assert not any(p.code == "discontinuity" for p in problems)
    good = segments_from_csv("x_from,x_to,slope,intercept\n0,10,1,0\n10,20,-0.5,15\n")
    assert check(good) == []
    table = segments_to_table(good)
    np.testing.assert_allclose(table.position, [0, 10, 20])
    np.testing.assert_allclose(table.error_at([5.0, 15.0]), [5.0, 7.5])
    # table -> segments -> table reproduces the table
    back = segments_to_table(table_to_segments(table))
    np.testing.assert_allclose(back.error_mean, table.error_mean)


def test_correction_quantity_is_negated_into_errors():
    model = segments_from_csv("# quantity: correction\nx_from,x_to,slope,intercept\n0,10,1,0\n")
    np.testing.assert_allclose(segments_to_table(model).error_mean, [0.0, -10.0])


# ---------------------------------------------------------------- table validation and CLI

def write(tmp_path: Path, name: str, text: str) -> Path:
    p = tmp_path / name
    p.write_text(text)
    return p


def test_good_table_exits_zero_with_one_line_ok(tmp_path):
    p = write(tmp_path, "good.csv", table_to_csv(awkward_table("linear")))
    result = runner.invoke(app, ["compensation", "check", str(p)])
    assert result.exit_code == 0, result.stdout
    assert result.stdout.strip().startswith("OK:")
    assert len(result.stdout.strip().splitlines()) == 1


@pytest.mark.parametrize("rows, code, line, words", [
    ("0,0,0\n20,1,1\n10,2,2\n", "unsorted", 6, "position 10 mm comes after 20 mm"),
    ("0,0,0\n10,1,1\n10,2,2\n", "duplicate", 6, "10 mm repeats line 5"),
    ("0,0,0\n10,nan,1\n20,2,2\n", "non-finite", 5, "error_up is nan"),
    ("0,0,0\n10,1,inf\n20,2,2\n", "non-finite", 5, "error_down is inf"),
])
def test_bad_tables_are_named(tmp_path, rows, code, line, words):
    text = "# kind: linear\n# mode: bidirectional\nposition,error_up,error_down\n" + rows
    p = write(tmp_path, "bad.csv", text)
    problems = check(read_compensation(p))
    hits = [q for q in problems if q.code == code]
    assert hits and hits[0].line == line
    result = runner.invoke(app, ["compensation", "check", str(p)])
    assert result.exit_code == 1
    out = one_line(result.stdout)
    assert f"line {line}" in out and words in out


def test_unreadable_file_exits_two_naming_line_and_column(tmp_path):
    p = write(tmp_path, "bad.csv", "position,error_mean\n0,1\n10,abc\n")
    result = runner.invoke(app, ["compensation", "check", str(p)])
    assert result.exit_code == 2
    err = one_line(result.stderr)
    assert "line 3" in err and "column 'error_mean'" in err and "Traceback" not in err


def test_max_step_warning_fails_the_check(tmp_path):
    table = CompensationTable.averaged("linear", [0.0, 10.0, 20.0], [0.0, 1.0, 9.0])
    p = write(tmp_path, "step.csv", table_to_csv(table))
    assert runner.invoke(app, ["compensation", "check", str(p)]).exit_code == 0
    result = runner.invoke(app, ["compensation", "check", str(p), "--max-step", "5"])
    assert result.exit_code == 1
    assert "changes by 8" in one_line(result.stdout)


def test_cli_convert_and_build(tmp_path):
    rec = write(tmp_path, "rec.csv", synthetic_recording())
    out_csv = tmp_path / "z.csv"
    r = runner.invoke(app, ["compensation", "build", str(rec), "--out", str(out_csv)])
    assert r.exit_code == 0, r.stderr
    built = read_compensation(out_csv)
    np.testing.assert_allclose(built.error_up, [2.0, 5.5, 6.0], atol=1e-12)
    comp = tmp_path / "z.comp"
    r = runner.invoke(app, ["compensation", "convert", str(out_csv), str(comp), "--to", "linuxcnc1"])
    assert r.exit_code == 0, r.stderr
    assert read_compensation(comp, "linuxcnc1").equals(built)
    r = runner.invoke(app, ["compensation", "check", str(comp), "--format", "linuxcnc1"])
    assert r.exit_code == 0
    out_json = tmp_path / "avg.json"
    r = runner.invoke(app, ["compensation", "build", str(rec), "--out", str(out_json), "--mode", "averaged"])
    assert r.exit_code == 0, r.stderr
    assert read_compensation(out_json).backlash == pytest.approx(4.0)
    # a discontinuous segment model cannot become a LinuxCNC table
    seg = write(tmp_path, "seg.csv", "x_from,x_to,slope,intercept\n0,10,0,0\n10,20,0,5\n")
    r = runner.invoke(app, ["compensation", "convert", str(seg), str(tmp_path / "s.comp")])
    assert r.exit_code != 0
    assert "jump of +5" in one_line(r.stdout)
    assert not (tmp_path / "s.comp").exists()


def test_bad_metadata_numbers_are_format_errors():
    """Found by the fuzzer: a malformed '# backlash:' line, and a JSON backlash that is
    not a number, must be refused with the file named, not crash."""
    from station.compensation.files import FormatError, from_json, table_from_csv

    with pytest.raises(FormatError, match="t.csv, column 'backlash': metadata 'backlash' is not a number"):
        table_from_csv("# kind: linear\n# mode: averaged\n# backlash:: 0.0\nposition,error_mean\n0.0,0.0\n30.0,1.5\n",
                       "t.csv")
    with pytest.raises(FormatError):
        from_json('{"kind": "linear", "position": [0, 10], "error_mean": [0, 1], "backlash": [1]}', "t.json")
