"""``make test``'s split of the suite (tests/suite_layout.py): the computation-only files run
at a lower priority beside the real-time tests, so a real-time file must never be taken
for one."""

from __future__ import annotations

import pytest
from suite_layout import REPO, is_compute_file

#: files that run the station's loop, twins over TCP or a pty, threads or child processes
REAL_TIME = ["tests/unit/test_engine.py", "tests/unit/test_stallwatch.py", "tests/unit/test_loopthread.py",
             "tests/unit/test_cycle.py", "tests/unit/test_engine_seams.py", "tests/sim/test_camera_twin.py",
             "tests/sim/test_runtime.py", "tests/unit/test_store.py", "tests/unit/test_master.py"]
#: files of rendering, fitting and models only
COMPUTE = ["tests/unit/test_vision.py", "tests/unit/test_vision_bound.py", "tests/unit/test_discovery_parts.py",
           "tests/unit/test_kinematics.py"]


@pytest.mark.parametrize("rel", REAL_TIME)
def test_real_time_files_are_not_computation(rel):
    assert (REPO / rel).is_file(), rel
    assert not is_compute_file(rel)


@pytest.mark.parametrize("rel", COMPUTE)
def test_computation_files_are_marked(rel):
    assert (REPO / rel).is_file(), rel
    assert is_compute_file(rel)


def test_only_unit_and_sim_files_can_be_computation():
    others = [p.relative_to(REPO).as_posix() for p in (REPO / "tests").rglob("test_*.py")
              if not p.relative_to(REPO).as_posix().startswith(("tests/unit/", "tests/sim/"))]
    assert others and not any(is_compute_file(rel) for rel in others)
