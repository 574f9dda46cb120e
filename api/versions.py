"""Versioned files the engineer uploads (compensation models, camera calibrations).

Each kind has a folder in the data folder (``models/``, ``calibrations/``): version
``n`` is ``<n>.<ext>``, never changed after upload, and ``index.json`` lists the
versions (who uploaded what, when, its sha256) and which one is active. Keeping every
version, rather than overwriting one file, lets an inspection's traceability name the
exact model it was compensated with, and lets an engineer go back.
"""

from __future__ import annotations

import hashlib
import json
import os
import threading
from datetime import datetime, timezone
from pathlib import Path
from typing import Any


class VersionStore:
    def __init__(self, folder: Path, ext: str):
        self.folder = Path(folder)
        self.ext = ext
        self._lock = threading.Lock()  # requests run these in worker threads

    @property
    def _index_path(self) -> Path:
        return self.folder / "index.json"

    def _read(self) -> dict[str, Any]:
        try:
            return json.loads(self._index_path.read_text())
        except FileNotFoundError:
            return {"active": None, "versions": []}

    def _write(self, index: dict[str, Any]) -> None:
        tmp = self._index_path.with_suffix(".tmp")
        tmp.write_text(json.dumps(index, indent=2) + "\n")
        os.replace(tmp, self._index_path)

    def index(self) -> dict[str, Any]:
        with self._lock:
            return self._read()

    def add(self, text: str, *, who: str, name: str, filename: str) -> dict[str, Any]:
        with self._lock:
            self.folder.mkdir(parents=True, exist_ok=True)
            index = self._read()
            version = 1 + max((v["version"] for v in index["versions"]), default=0)
            path = self.folder / f"{version}.{self.ext}"
            with open(path, "x", encoding="utf-8") as f:  # "x": a version is never overwritten
                f.write(text)
            entry = {"version": version, "name": name, "filename": filename,
                     "sha256": hashlib.sha256(text.encode()).hexdigest(), "size": len(text.encode()),
                     "uploaded_by": who, "uploaded_at": datetime.now(timezone.utc).isoformat()}
            index["versions"].append(entry)
            self._write(index)
            return {**entry, "active": False}

    def text(self, version: int) -> str:
        return (self.folder / f"{version}.{self.ext}").read_text(encoding="utf-8")

    def entry(self, version: int) -> dict[str, Any] | None:
        for v in self.index()["versions"]:
            if v["version"] == version:
                return v
        return None

    def activate(self, version: int) -> None:
        with self._lock:
            index = self._read()
            if not any(v["version"] == version for v in index["versions"]):
                raise KeyError(version)
            index["active"] = version
            self._write(index)
