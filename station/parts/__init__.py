"""Part specs: what a part must be (bore, compensating holes, tolerances).

``load_part("ZDZG-22.2-12.3851")`` gives a built-in spec by part number,
``load_part("my-part.toml")`` reads a file; ``list_parts()`` lists the built-ins.
The file format is described in ``docs/part-specs.md``.
"""

from station.parts.loader import (
    PartSpecError,
    Problem,
    builtin_part_numbers,
    list_parts,
    load_part,
    parse_part,
    read_part_file,
)
from station.parts.spec import Bore, Characteristic, Hole, PartSpec, Tolerance

__all__ = [
    "Bore", "Characteristic", "Hole", "PartSpec", "PartSpecError", "Problem", "Tolerance",
    "builtin_part_numbers", "list_parts", "load_part", "parse_part", "read_part_file",
]
