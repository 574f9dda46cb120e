"""ISO 230-2:2014 analysis: figures against hand-computed values, conventions, CLI, plot."""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pytest
from typer.testing import CliRunner

from station.cli import app
from station.iso230 import analyse, group_targets
from station.recording import parse_recording

SQRT2 = math.sqrt(2.0)

# 3 targets x 2 runs, both directions.  Hand computation (um):
#   target 0 : up {1, 2}  -> x̄↑ 1.5, s↑ = sqrt(0.25+0.25)/1 = √0.5 = 0.7071
#              down {-1, 0} -> x̄↓ -0.5, s↓ = √0.5;  B_0 = 1.5 - (-0.5) = 2.0;  x̄ = 0.5
#   target 10: up {2, 4}  -> x̄↑ 3.0, s↑ = √2 = 1.4142
#              down {0, 1} -> x̄↓ 0.5,  s↓ = √0.5;   B_10 = 2.5;  x̄ = 1.75
#   target 20: up {3, 3}  -> x̄↑ 3.0, s↑ = 0
#              down {1, 2} -> x̄↓ 1.5,  s↓ = √0.5;   B_20 = 1.5;  x̄ = 2.25
# B  = max|B_i| = 2.5            B̄ = (2 + 2.5 + 1.5)/3 = 2.0
# R↑ = 4 max s↑ = 4√2            R↓ = 4√0.5 = 2√2
# R_i = max(2s↑ + 2s↓ + |B_i|, 4s↑, 4s↓):
#   t0: √2 + √2 + 2 = 2 + 2√2;  t10: 2√2 + √2 + 2.5 = 2.5 + 3√2;  t20: 0 + √2 + 1.5
#   R = 2.5 + 3√2  (= 6.7426; larger than R↑ = 5.657)
# E↑ = 3 - 1.5 = 1.5   E↓ = 1.5 - (-0.5) = 2.0   E = 3 - (-0.5) = 3.5
# M  = 2.25 - 0.5 = 1.75
# A↑ = max(x̄↑+2s↑) - min(x̄↑-2s↑) = (3 + 2√2) - (1.5 - √2) = 1.5 + 3√2
# A↓ = (1.5 + √2) - (-0.5 - √2) = 2 + 2√2
# A  = (3 + 2√2) - (-0.5 - √2) = 3.5 + 3√2
FIXTURE = """# axis: Z
# kind: linear
time_s,run,direction,target,deviation
0,1,+1,0,1.0
1,1,+1,10,2.0
2,1,+1,20,3.0
3,1,-1,20,1.0
4,1,-1,10,0.0
5,1,-1,0,-1.0
6,2,+1,0,2.0
7,2,+1,10,4.0
8,2,+1,20,3.0
9,2,-1,20,2.0
10,2,-1,10,1.0
11,2,-1,0,0.0
"""

EXPECTED = {
    "B": 2.5, "B_mean": 2.0,
    "R_up": 4 * SQRT2, "R_down": 2 * SQRT2, "R": 2.5 + 3 * SQRT2,
    "E_up": 1.5, "E_down": 2.0, "E": 3.5, "M": 1.75,
    "A_up": 1.5 + 3 * SQRT2, "A_down": 2 + 2 * SQRT2, "A": 3.5 + 3 * SQRT2,
}


def rows_to_csv(rows, kind="linear") -> str:
    """rows: (run, direction, target, deviation); time is the row index."""
    lines = [f"# kind: {kind}", "time_s,run,direction,target,deviation"]
    lines += [f"{i},{r},{d:+d},{t!r},{x!r}" for i, (r, d, t, x) in enumerate(rows)]
    return "\n".join(lines) + "\n"


def test_figures_match_hand_computation():
    result = analyse(parse_recording(FIXTURE))
    for name, value in EXPECTED.items():
        assert getattr(result, name) == pytest.approx(value, abs=1e-12), name
    st = result.stats
    np.testing.assert_allclose(st.target, [0, 10, 20])
    np.testing.assert_allclose(st.mean_up, [1.5, 3.0, 3.0])
    np.testing.assert_allclose(st.mean_down, [-0.5, 0.5, 1.5])
    np.testing.assert_allclose(st.s_up, [math.sqrt(0.5), SQRT2, 0.0], atol=1e-15)
    np.testing.assert_allclose(st.s_down, [math.sqrt(0.5)] * 3)
    np.testing.assert_allclose(st.reversal, [2.0, 2.5, 1.5])
    assert result.unit == "um" and result.kind == "linear"


def test_json_has_exactly_the_contract_keys():
    out = analyse(parse_recording(FIXTURE)).to_json()
    assert set(out) == set(EXPECTED) | {"targets", "unit", "kind", "warnings"}
    assert set(out["targets"][0]) == {"target", "mean_up", "mean_down", "s_up", "s_down", "n_up", "n_down", "B_i"}
    assert out["targets"][1] == {"target": 10.0, "mean_up": 3.0, "mean_down": 0.5, "s_up": pytest.approx(SQRT2),
                                 "s_down": pytest.approx(math.sqrt(0.5)), "n_up": 2, "n_down": 2, "B_i": 2.5}
    json.dumps(out, allow_nan=False)  # serialisable without NaN


def test_reversal_sign_follows_direction_convention():
    # up approach reads 3 um larger than down at every target -> B_i = +3
    rows = [(r, d, t, (1.5 if d > 0 else -1.5) + 0.1 * r) for r in (1, 2) for d in (1, -1) for t in (0.0, 50.0)]
    result = analyse(parse_recording(rows_to_csv(rows)))
    assert result.B_mean == pytest.approx(3.0)
    np.testing.assert_allclose(result.stats.reversal, [3.0, 3.0])
    # the same numbers with the directions swapped: B_i negative, B (a magnitude) unchanged
    swapped = [(r, -d, t, x) for r, d, t, x in rows]
    result = analyse(parse_recording(rows_to_csv(swapped)))
    assert result.B_mean == pytest.approx(-3.0)
    assert result.B == pytest.approx(3.0)


def test_targets_are_grouped_with_a_tolerance_relative_to_the_range():
    # range 100 mm -> tolerance 1e-4 mm: 50 and 50 + 1e-7 are one target, 50.01 is another
    group, targets = group_targets(np.array([0.0, 50.0, 50.0 + 1e-7, 50.01, 100.0]))
    assert targets.size == 4
    assert group[1] == group[2] != group[3]
    rows = [(1, 1, 0.0, 0.0), (1, 1, 50.0, 1.0), (2, 1, 50.0 + 1e-7, 3.0), (1, 1, 100.0, 0.0)]
    st = analyse(parse_recording(rows_to_csv(rows))).stats
    assert st.n_up.tolist() == [1, 2, 1]
    assert st.mean_up[1] == pytest.approx(2.0)


def test_single_approach_has_no_s_and_is_left_out_of_R_and_A():
    # targets 0 and 10: two approaches each way.  Target 20: ONE up approach, far off (+50 um).
    rows = []
    for r in (1, 2):
        for t in (0.0, 10.0):
            rows.append((r, 1, t, 1.0 + r))   # up {2, 3}: mean 2.5, s = √0.5
            rows.append((r, -1, t, 0.0 + r))  # down {1, 2}: mean 1.5, s = √0.5
    rows.append((1, 1, 20.0, 50.0))
    rows.append((1, -1, 20.0, 49.0))
    rows.append((2, -1, 20.0, 49.0))           # down at 20: {49, 49}: s = 0
    result = analyse(parse_recording(rows_to_csv(rows)))
    out = result.to_json()
    t20 = out["targets"][2]
    assert t20["n_up"] == 1 and t20["s_up"] is None and t20["mean_up"] == 50.0
    assert t20["B_i"] == pytest.approx(1.0)
    # R↑ and A↑ come from targets 0 and 10 only: R↑ = 4√0.5, A↑ = (2.5+√2) - (2.5-√2) = 2√2
    assert result.R_up == pytest.approx(4 * math.sqrt(0.5))
    assert result.A_up == pytest.approx(2 * SQRT2)
    # bidirectional R_i needs s↑: target 20 is left out, R = √2 + √2 + 1 = 1 + 2√2
    assert result.R == pytest.approx(1 + 2 * SQRT2)
    # the mean still counts where s is not needed: E↑ spans 2.5 .. 50
    assert result.E_up == pytest.approx(47.5)
    # A↓ uses target 20's down band (s = 0): max 49, min 1.5 - √2
    assert result.A_down == pytest.approx(49 - (1.5 - SQRT2))
    assert any("only one up approach" in w and "20" in w for w in result.warnings)


def test_missing_direction_and_uneven_counts():
    rows = [(1, 1, 0.0, 1.0), (2, 1, 0.0, 2.0), (3, 1, 0.0, 6.0),  # three up approaches
            (1, -1, 0.0, 0.0), (2, -1, 0.0, 1.0),                 # two down
            (1, 1, 5.0, 0.0), (2, 1, 5.0, 0.0)]                   # target 5: up only
    result = analyse(parse_recording(rows_to_csv(rows)))
    st = result.stats
    # up at 0: {1, 2, 6}: mean 3, s = sqrt((4 + 1 + 9) / 2) = √7
    assert st.mean_up[0] == pytest.approx(3.0)
    assert st.s_up[0] == pytest.approx(math.sqrt(7.0))
    assert st.n_down.tolist() == [2, 0]
    assert np.isnan(st.reversal[1])
    assert result.B == pytest.approx(2.5)  # only target 0 has both directions
    assert result.M == pytest.approx(0.0)  # one bidirectional mean
    assert result.to_json()["targets"][1]["mean_down"] is None
    assert any("no down (-1) approach" in w and "5" in w for w in result.warnings)
    assert any("uneven" in w for w in result.warnings)


def test_rotary_recording_reports_arcsec():
    rows = [(r, d, t, 1.0 * r + d) for r in (1, 2) for d in (1, -1) for t in (0.0, 90.0, 180.0)]
    result = analyse(parse_recording(rows_to_csv(rows, kind="rotary")))
    assert result.unit == "arcsec" and result.kind == "rotary"
    assert result.B == pytest.approx(2.0)


# ---------------------------------------------------------------- CLI

runner = CliRunner()


@pytest.fixture()
def fixture_csv(tmp_path) -> Path:
    p = tmp_path / "rec.csv"
    p.write_text(FIXTURE)
    return p


def test_cli_json_is_one_object_with_the_figures(fixture_csv):
    result = runner.invoke(app, ["iso230", str(fixture_csv), "--json"])
    assert result.exit_code == 0, result.stderr
    out = json.loads(result.stdout)  # the whole of stdout is one JSON document
    for name, value in EXPECTED.items():
        assert out[name] == pytest.approx(value), name
    assert out["unit"] == "um" and out["kind"] == "linear"


def test_cli_table_report(fixture_csv):
    result = runner.invoke(app, ["iso230", str(fixture_csv)])
    assert result.exit_code == 0
    text = result.stdout
    assert "6.743" in text  # R
    assert "7.743" in text  # A
    assert "reversal value" in text


@pytest.mark.parametrize("body, line, column", [
    ("time_s,run,direction,target,deviation\n0,1,+1,0,1\n1,1,+2,0,1\n", 3, "direction"),
    ("time_s,run,direction,target,deviation\n0,1,+1,0,1\n1,1,-1,0,abc\n", 3, "deviation"),
    ("time_s,run,direction,target\n0,1,+1,0\n", 1, "deviation"),
])
def test_cli_bad_input_names_line_and_column(tmp_path, body, line, column):
    p = tmp_path / "bad.csv"
    p.write_text(body)
    result = runner.invoke(app, ["iso230", str(p), "--json"])
    assert result.exit_code != 0
    assert result.stdout == ""
    message = " ".join(result.stderr.split())  # rich wraps long lines
    assert f"line {line}" in message and f"column '{column}'" in message and "bad.csv" in message
    assert "Traceback" not in result.stderr
    assert not isinstance(result.exception, (ValueError, TypeError, KeyError))


def test_cli_missing_file_is_a_clear_error(tmp_path):
    result = runner.invoke(app, ["iso230", str(tmp_path / "nope.csv")])
    assert result.exit_code != 0
    assert "no such file" in " ".join(result.stderr.split())


def test_cli_plot_is_a_png(fixture_csv, tmp_path):
    png = tmp_path / "iso.png"
    result = runner.invoke(app, ["iso230", str(fixture_csv), "--json", "--plot", str(png)])
    assert result.exit_code == 0, result.stderr
    json.loads(result.stdout)  # the plot note went to stderr, not into the JSON
    assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    assert png.stat().st_size > 10_000
