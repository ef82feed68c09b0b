"""CI gates on evaluated values: ``--fail-under``, ``--fail-over`` and ``--max-regression``.

A gate names a stored value as ``METRIC.VALUE`` (``nuscenes_detection.mAP``,
``latency.frame_p95_ms``, ``clear_mot.MOTA/vehicle``: the metric is the text before the first
dot) and a threshold:

* ``--fail-under METRIC.VALUE=X`` fails when the value is below X;
* ``--fail-over METRIC.VALUE=X`` fails when the value is above X;
* ``--max-regression [METRIC.]VALUE=X`` (A/B) fails when B is worse than A by more than X in the
  value's own direction (``higher_is_better``); without ``METRIC.`` every metric that has a value
  of that name is gated.

A value that is missing or NaN fails its gate (a gate that checks nothing must not pass), and so
does a regression gate on a value without a direction.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Literal

from redrive.errors import ConfigError

__all__ = ["Gate", "GateCheck", "GateKind", "check_regression", "check_threshold", "parse_gate"]

GateKind = Literal["under", "over", "regression"]

_FLAG = {"under": "--fail-under", "over": "--fail-over", "regression": "--max-regression"}


@dataclass(frozen=True, slots=True, kw_only=True)
class Gate:
    """One gate: ``metric`` ("" for a regression gate on every metric with a value ``key``),
    ``key`` (the value's name), ``threshold`` (a margin for a regression gate)."""

    kind: GateKind
    metric: str
    key: str
    threshold: float

    @property
    def name(self) -> str:
        return f"{self.metric}.{self.key}" if self.metric else self.key

    @property
    def text(self) -> str:
        return f"{_FLAG[self.kind]} {self.name}={self.threshold:g}"


@dataclass(frozen=True, slots=True, kw_only=True)
class GateCheck:
    """A gate checked on one value: where (pipeline, loop, algorithm …), the value (the B − A
    difference for a regression gate), whether it passed, and a note when it could not be
    checked."""

    gate: Gate
    where: str
    value: float
    passed: bool
    note: str = ""

    @property
    def threshold_text(self) -> str:
        t = self.gate.threshold
        return {"under": f">= {t:g}", "over": f"<= {t:g}", "regression": f"worse by <= {t:g}"}[
            self.gate.kind
        ]


def parse_gate(text: str, kind: GateKind) -> Gate:
    """``METRIC.VALUE=X`` (for ``regression`` also ``VALUE=X``) as a :class:`Gate`.

    Raises:
        ConfigError: no ``=``, no metric, or X is not a number.
    """
    name, sep, number = text.rpartition("=")
    flag = _FLAG[kind]
    example = "mAP=0.01" if kind == "regression" else "nuscenes_detection.mAP=0.40"
    if not sep or not name.strip():
        msg = f"{flag} {text!r}: expected METRIC.VALUE=NUMBER, e.g. {flag} {example}"
        raise ConfigError(msg)
    try:
        threshold = float(number)
    except ValueError as err:
        msg = f"{flag} {text!r}: {number!r} is not a number (e.g. {flag} {example})"
        raise ConfigError(msg) from err
    if math.isnan(threshold):
        msg = f"{flag} {text!r}: the threshold is NaN"
        raise ConfigError(msg)
    metric, dot, key = name.strip().partition(".")
    if not dot:
        if kind != "regression":
            msg = (
                f"{flag} {text!r}: name the metric and its value, METRIC.VALUE=NUMBER "
                f"(e.g. {flag} {example}; `redrive evaluate RUN` lists them)"
            )
            raise ConfigError(msg)
        metric, key = "", metric
    if kind == "regression" and threshold < 0:
        msg = f"{flag} {text!r}: the margin must be >= 0"
        raise ConfigError(msg)
    return Gate(kind=kind, metric=metric, key=key, threshold=threshold)


def check_threshold(gate: Gate, value: float | None, *, where: str) -> GateCheck:
    """A ``--fail-under``/``--fail-over`` gate on ``value`` (None: the value does not exist)."""
    if value is None or math.isnan(value):
        note = "no such value" if value is None else "the value is NaN (undefined)"
        return GateCheck(gate=gate, where=where, value=math.nan, passed=False, note=note)
    passed = value >= gate.threshold if gate.kind == "under" else value <= gate.threshold
    return GateCheck(gate=gate, where=where, value=value, passed=passed)


def check_regression(
    gate: Gate, a: float, b: float, higher_is_better: bool | None, *, where: str
) -> GateCheck:
    """A ``--max-regression`` gate: B may be worse than A by at most the margin.

    ``value`` of the check is how much worse B is (positive: worse, in the value's unit)."""
    if higher_is_better is None:
        return GateCheck(
            gate=gate, where=where, value=b - a, passed=False,
            note="the value has no direction (neither higher nor lower is better)",
        )  # fmt: skip
    if math.isnan(a) or math.isnan(b):
        return GateCheck(gate=gate, where=where, value=math.nan, passed=False, note="A or B is NaN")
    worse_by = (a - b) if higher_is_better else (b - a)
    return GateCheck(gate=gate, where=where, value=worse_by, passed=worse_by <= gate.threshold)
