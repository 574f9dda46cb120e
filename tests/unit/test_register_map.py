"""The register map's declaration (drivers.interfaces.register_map) against its
document, docs/register-map.md, and its codecs against hand-made words.

The document is read here as a reader reads it (its tables), so a field whose
address, width, sign, units or access drifts from the page fails; the codecs are
checked on values whose register words are written out by hand (two's complement,
high word first), not computed with the code under test.
"""

from __future__ import annotations

import re
from pathlib import Path

import pytest

from drivers.interfaces import register_map as rm

DOC = Path(__file__).resolve().parents[2] / "docs" / "register-map.md"


def doc_table(heading: str | None) -> list[list[str]]:
    """The rows (cells stripped) of the first table after ``heading`` (None: the first table)."""
    lines = DOC.read_text(encoding="utf-8").splitlines()
    i = 0 if heading is None else next(n for n, line in enumerate(lines) if line.strip() == heading)
    while not lines[i].startswith("|"):
        i += 1
    rows = []
    for line in lines[i + 2:]:  # past the header and its rule
        if not line.startswith("|"):
            break
        rows.append([cell.strip() for cell in line.strip().strip("|").split("|")])
    return rows


def doc_registers() -> dict[str, dict]:
    out = {}
    for addr, name, typ, units, access, _meaning in doc_table(None):
        first, _, last = addr.partition("-")
        out[name] = {"first": int(first), "last": int(last or first), "type": typ, "units": units,
                     "access": access}
    return out


def test_every_documented_register_is_declared_as_the_page_says():
    doc = doc_registers()
    declared = {f.name: f for f in rm.REGISTERS}
    assert sorted(declared) == sorted(doc)
    for name, row in doc.items():
        f = declared[name]
        assert (f.address, f.address + f.count - 1) == (row["first"], row["last"]), name
        assert f.type == row["type"], name
        assert f.width == {"16": 16, "32": 32}[re.search(r"(\d+)$", row["type"]).group(1)], name
        assert f.signed == row["type"].startswith("int"), name
        assert f.units == row["units"], name
        assert f.access == row["access"], name
        # what is counted scales with the axis (counts, counts/s, counts/s^2); the rest is raw
        assert (f.scale is rm.Scale.COUNTS) == row["units"].startswith("counts"), name


def test_the_register_count_and_the_blocks_are_the_pages():
    text = DOC.read_text(encoding="utf-8")
    # "Writing a read-only register, or any address >= 18, answers exception 2"
    assert rm.REGISTER_COUNT == int(re.search(r"any address >= (\d+)", text).group(1)) == 18
    # "Layout: 1..6 is the status snapshot (one request of 6 registers); 8..13 is a whole move"
    assert (rm.STATUS_BLOCK.start, rm.STATUS_BLOCK.count) == (1, 6)
    assert (rm.MOVE_BLOCK.start, rm.MOVE_BLOCK.count) == (8, 6)
    assert (rm.STATUS_BLOCK_START, rm.STATUS_BLOCK_COUNT) == (1, 6)
    # the plain constants are the declaration's addresses
    for f in rm.REGISTERS:
        assert getattr(rm, f.name) == f.address
    assert rm.REGISTERS.at(3) is rm.REGISTERS.ACTUAL_POSITION and rm.REGISTERS.at(18) is None


@pytest.mark.parametrize("heading, flags", [("## Control word (address 0)", rm.ControlBit),
                                            ("## Status word (address 1)", rm.StatusBit)])
def test_bits_are_the_pages(heading, flags):
    doc = {name: 1 << int(bit) for bit, name, *_ in doc_table(heading)}
    assert {f.name: int(f) for f in flags} == doc


def test_fault_codes_are_the_pages():
    doc = {int(code, 16) for code, _meaning in doc_table("## Fault codes (address 6)")}
    assert {int(c) for c in rm.FaultCode} == doc


def test_decoding_by_hand_made_words():
    # -2 counts: 0xFFFFFFFE, high word first; 65536 + 10 counts: 0x0001000A
    regs = [0x001B, 0xFFFF, 0xFFFE, 0x0001, 0x000A, 0x0010]
    raw = rm.STATUS_BLOCK.decode_raw(regs)
    assert raw == {"STATUS_WORD": 0x1B, "ACTUAL_POSITION": -2, "ACTUAL_VELOCITY": 65546, "FAULT_CODE": 0x10}
    scaled = rm.STATUS_BLOCK.decode(regs, unit_per_count=1e-4)
    assert scaled["ACTUAL_POSITION"] == pytest.approx(-2e-4) and scaled["ACTUAL_VELOCITY"] == pytest.approx(6.5546)
    assert scaled["STATUS_WORD"] == 0x1B and isinstance(scaled["FAULT_CODE"], int)  # raw fields stay ints
    # a uint32 with its top bit set is not negative
    assert rm.REGISTERS.PROFILE_VELOCITY.decode_raw([0x8000, 0x0000]) == 2**31
    # each register is taken as its 16 bits (a client that hands back more is not trusted)
    assert rm.REGISTERS.FAULT_CODE.decode_raw([0x1_0010]) == 0x0010


def test_encoding_by_hand_made_words_and_its_limits():
    move = rm.MOVE_BLOCK.encode_raw({"TARGET_POSITION": -1, "PROFILE_VELOCITY": 200_000,
                                     "PROFILE_ACCELERATION": 2_000_000})
    assert move == [0xFFFF, 0xFFFF, 0x0003, 0x0D40, 0x001E, 0x8480]
    target = rm.REGISTERS.TARGET_POSITION
    assert target.encode(42.0, unit_per_count=1e-4) == [0x0006, 0x68A0]  # 420000 counts
    assert target.decode(target.encode(-12.3456, 1e-4), 1e-4) == pytest.approx(-12.3456)
    with pytest.raises(OverflowError):
        target.encode_raw(2**31)
    with pytest.raises(OverflowError):
        rm.REGISTERS.PROFILE_VELOCITY.encode_raw(-1)
    with pytest.raises(OverflowError):
        rm.REGISTERS.WATCHDOG_TIMEOUT_MS.encode_raw(0x10000)
    with pytest.raises(ValueError, match="unit_per_count"):
        target.decode([0, 1])  # counts need the axis' scale
    with pytest.raises(KeyError):
        rm.MOVE_BLOCK.encode_raw({"TARGET_POSITION": 1})
    # the helpers the twin uses are the same codec
    assert rm.int32_to_regs(-5) == [0xFFFF, 0xFFFB] and rm.regs_to_int32(0xFFFF, 0xFFFB) == -5
    assert rm.uint32_to_regs(70_000) == [0x0001, 0x1170] and rm.regs_to_uint32(1, 0x1170) == 70_000


def test_a_declaration_that_contradicts_itself_is_refused():
    with pytest.raises(ValueError, match="share register"):
        rm.RegisterMap([rm.Field("A", 0, 32), rm.Field("B", 1)])
    with pytest.raises(ValueError, match="16 or 32"):
        rm.Field("A", 0, 8)
    with pytest.raises(ValueError, match="does not follow"):
        rm.Block("gap", (rm.REGISTERS.STATUS_WORD, rm.REGISTERS.FAULT_CODE))
