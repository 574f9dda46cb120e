"""The station's topology as data: the lower-order body array (paper, Table 1).

``L1(j)`` is the parent of body ``j``; ``L^n(j) = L1(L^(n-1)(j))`` walks n steps
towards the root. The two kinematic chains (root -> tool, root -> workpiece) are
derived from this array, never hard-coded.
"""

from __future__ import annotations

import tomllib
from dataclasses import dataclass
from importlib import resources
from pathlib import Path


class TopologyError(ValueError):
    pass


@dataclass(frozen=True)
class Body:
    index: int
    name: str
    parent: int | None
    description: str = ""
    joint: str | None = None  # "prismatic_z", "revolute_z" or None (static)


@dataclass(frozen=True)
class Topology:
    bodies: tuple[Body, ...]
    tool: int
    workpiece: int

    def __post_init__(self):
        for i, b in enumerate(self.bodies):
            if b.index != i:
                raise TopologyError(f"body {b.name!r} has index {b.index}, expected {i}")
            if b.parent is not None and not (0 <= b.parent < len(self.bodies)):
                raise TopologyError(f"body {b.name!r} has unknown parent {b.parent}")
        roots = [b for b in self.bodies if b.parent is None]
        if len(roots) != 1:
            raise TopologyError(f"expected exactly one root body, found {[b.name for b in roots]}")
        for b in self.bodies:  # no cycles: every body reaches the root
            self.path_to_root(b.index)

    @property
    def root(self) -> int:
        return next(b.index for b in self.bodies if b.parent is None)

    def by_name(self, name: str) -> Body:
        for b in self.bodies:
            if b.name == name:
                return b
        raise KeyError(name)

    def lower(self, j: int, n: int = 1) -> int | None:
        """``L^n(j)``: the body n steps below ``j`` towards the root (None past the root)."""
        out: int | None = j
        for _ in range(n):
            if out is None:
                return None
            out = self.bodies[out].parent
        return out

    def lower_order_array(self) -> list[list[int | None]]:
        """Rows L^0 .. L^k of Table 1 (k = deepest chain), None for '-'."""
        depth = max(len(self.path_to_root(b.index)) for b in self.bodies)
        return [[self.lower(b.index, n) for b in self.bodies] for n in range(depth)]

    def path_to_root(self, j: int) -> list[int]:
        path = [j]
        while self.bodies[path[-1]].parent is not None:
            path.append(self.bodies[path[-1]].parent)  # type: ignore[arg-type]
            if len(path) > len(self.bodies):
                raise TopologyError(f"cycle in the body array through {self.bodies[j].name!r}")
        return path

    def chain(self, j: int) -> list[int]:
        """Bodies from the root (excluded) out to ``j``: the order transforms multiply in."""
        return list(reversed(self.path_to_root(j)))[1:]

    @property
    def tool_chain(self) -> list[int]:
        return self.chain(self.tool)

    @property
    def workpiece_chain(self) -> list[int]:
        return self.chain(self.workpiece)


def load_topology(path: str | Path | None = None) -> Topology:
    """Read a topology file; the default is the station's (``station/data/topology.toml``)."""
    if path is None:
        text = resources.files("station").joinpath("data/topology.toml").read_text(encoding="utf-8-sig")
        source = "station/data/topology.toml"
    else:
        text = Path(path).read_text(encoding="utf-8-sig")
        source = str(path)
    data = tomllib.loads(text)
    bodies = []
    tool = workpiece = None
    for i, b in enumerate(data.get("body", [])):
        try:
            bodies.append(Body(int(b["index"]), str(b["name"]), b.get("parent"), b.get("description", ""), b.get("joint")))
        except KeyError as exc:
            raise TopologyError(f"{source}: body[{i}] lacks {exc.args[0]!r}") from None
        if b.get("tool"):
            tool = int(b["index"])
        if b.get("workpiece"):
            workpiece = int(b["index"])
    if tool is None or workpiece is None:
        raise TopologyError(f"{source}: one body must be marked tool = true and one workpiece = true")
    return Topology(tuple(bodies), tool, workpiece)
