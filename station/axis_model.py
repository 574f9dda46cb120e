"""Axis models (contract ``shared/spec/discovery.md`` section 2).

What the simulation believes about one axis: a baseline error curve, the
repeatability, and effects from the vocabulary.  It is an :class:`ErrorCurve`
plus a name and a noise level, so the same object drives the twin, the
compensation and discovery.
"""

from __future__ import annotations

import dataclasses
import math
import tomllib
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import tomli_w

from station.effects import EffectSpecError, ErrorCurve, effect_from_dict
from station.recording import Recording


class AxisModelError(ValueError):
    """A model file that cannot be used; the message names file and field."""


@dataclass(frozen=True)
class AxisModel:
    name: str
    kind: str
    curve: ErrorCurve
    noise_sigma: float = 0.0
    #: anything else found in the file, written back unchanged
    extra: dict[str, Any] = field(default_factory=dict)

    def predict(self, recording: Recording) -> np.ndarray:
        """The deviation this model expects at every row of ``recording`` (no noise)."""
        return self.curve.evaluate(
            recording.target, recording.direction, recording.time_s, recording.temperature_c,
            recording.numeric_channels() or None,
        )

    def with_effects(self, *effects) -> "AxisModel":
        return dataclasses.replace(self, curve=self.curve.with_effects(*effects))

    def to_dict(self) -> dict[str, Any]:
        out: dict[str, Any] = {k: v for k, v in self.extra.items()}
        out["axis"] = {**self.extra.get("axis", {}), "name": self.name, "kind": self.kind}
        out["baseline"] = {"target": list(self.curve.target), "deviation": list(self.curve.deviation)}
        out["noise"] = {**self.extra.get("noise", {}), "sigma": self.noise_sigma}
        if self.curve.effects:
            out["effects"] = [e.to_dict() for e in self.curve.effects]
        return out

    def to_toml(self, path: str | Path | None = None) -> str:
        text = tomli_w.dumps(self.to_dict())
        if path is not None:
            Path(path).write_text(text)
        return text


def _float_list(value: Any, where: str) -> tuple[float, ...]:
    if not isinstance(value, list):
        raise AxisModelError(f"{where}: expected a list of numbers")
    out = []
    for i, v in enumerate(value):
        if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(float(v)):
            raise AxisModelError(f"{where}[{i}]: not a finite number: {v!r}")
        out.append(float(v))
    return tuple(out)


def axis_model_from_dict(data: dict[str, Any], source: str = "<dict>") -> AxisModel:
    axis = data.get("axis")
    if not isinstance(axis, dict):
        raise AxisModelError(f"{source}: missing [axis] table")
    name = str(axis.get("name", ""))
    kind = axis.get("kind")
    if kind not in ("linear", "rotary"):
        raise AxisModelError(f"{source}: [axis] kind must be 'linear' or 'rotary', not {kind!r}")
    base = data.get("baseline", {})
    if not isinstance(base, dict):
        raise AxisModelError(f"{source}: [baseline] must be a table")
    target = _float_list(base.get("target", []), f"{source}: baseline.target")
    deviation = _float_list(base.get("deviation", []), f"{source}: baseline.deviation")
    if len(target) != len(deviation):
        raise AxisModelError(
            f"{source}: baseline.target has {len(target)} values, baseline.deviation {len(deviation)}"
        )
    for i in range(1, len(target)):
        if target[i] <= target[i - 1]:
            raise AxisModelError(f"{source}: baseline.target[{i}] = {target[i]} is not above the one before")
    noise = data.get("noise", {})
    sigma = noise.get("sigma", 0.0) if isinstance(noise, dict) else None
    if isinstance(sigma, bool) or not isinstance(sigma, (int, float)) or sigma < 0 or not math.isfinite(sigma):
        raise AxisModelError(f"{source}: noise.sigma must be a non-negative number, not {sigma!r}")
    effects = []
    raw_effects = data.get("effects", [])
    if not isinstance(raw_effects, list):
        raise AxisModelError(f"{source}: effects must be an array of tables ([[effects]])")
    for i, e in enumerate(raw_effects):
        if not isinstance(e, dict):
            raise AxisModelError(f"{source}: effects[{i}] is not a table")
        try:
            eff = effect_from_dict(e, f"{source}: effects[{i}]")
        except EffectSpecError as exc:
            raise AxisModelError(str(exc)) from None
        if kind not in eff.kinds:
            raise AxisModelError(f"{source}: effects[{i}] {eff.name!r} does not apply to a {kind} axis")
        effects.append(eff)
    extra = {k: v for k, v in data.items() if k not in ("baseline", "effects")}
    try:
        curve = ErrorCurve(kind=kind, target=target, deviation=deviation, effects=tuple(effects))
    except ValueError as exc:  # a rotary baseline over a whole turn that does not close
        raise AxisModelError(f"{source}: baseline: {exc}") from None
    return AxisModel(name=name, kind=kind, curve=curve, noise_sigma=float(sigma), extra=extra)


def read_axis_model(path: str | Path) -> AxisModel:
    p = Path(path)
    try:
        data = tomllib.loads(p.read_text(encoding="utf-8"))
    except FileNotFoundError:
        raise AxisModelError(f"{p}: no such file") from None
    except tomllib.TOMLDecodeError as exc:
        raise AxisModelError(f"{p}: not valid TOML: {exc}") from None
    except UnicodeDecodeError:
        raise AxisModelError(f"{p}: not UTF-8 text") from None
    return axis_model_from_dict(data, str(p))
