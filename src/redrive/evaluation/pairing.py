"""Which two runs :func:`redrive.evaluation.compare.compare_runs` may put side by side, and what
the pairing is: what the runs were made from, open or closed loop, and whether their pipelines
agree.

* **Two runs of the same loop** (an A/B): the same log (its sha256), or, for two closed-loop
  runs of a scenario, the same scenario, seed, duration and agents mode.
* **An open-loop run beside a closed-loop run** (either order): the same pipeline driving the
  same situation, once on the log and once with its own decisions moving the car.  The situation
  is the same when the closed loop ran the scenario (name, seed, duration) the open-loop run's
  log was synthesized from (``redrive synth`` records it in the MCAP, a replay in the manifest's
  ``log.scenario``), or when both ran the same recorded log (sha256).  The closed loop's agents
  mode is stated: ``replay`` agents follow the script as in the log, ``reactive`` ones do not.

Either way the pipelines are compared (algorithms, their plugins, versions and configuration
hashes, and the pipeline seed); differences are stated, not refused — an A/B of two planners is
what ``compare`` is for, and an open/closed pair of different pipelines is still a pair.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

from redrive.errors import ConfigError
from redrive.results import Run

__all__ = ["CLOSED_LOOP", "OPEN_LOOP", "Pairing", "pair_runs", "run_loop"]

OPEN_LOOP = "open loop"
CLOSED_LOOP = "closed loop"


@dataclass(frozen=True, slots=True, kw_only=True)
class Pairing:
    """How run A and run B are paired.

    Attributes:
        open_closed: one run is open loop and the other closed loop (else an A/B of one loop).
        loop_a, loop_b: ``"open loop"`` or ``"closed loop"``.
        source: what both were made from (a log's sha256, or ``scenario NAME seed S duration D
            s`` …); the same for both.
        pipeline_differences: how B's pipeline differs from A's (empty: the same pipeline).
        notes: more that a reader needs (the closed loop's agents mode).
    """

    open_closed: bool
    loop_a: str
    loop_b: str
    source: str
    pipeline_differences: tuple[str, ...] = ()
    notes: tuple[str, ...] = ()

    @property
    def kind(self) -> str:
        """``open/closed`` for an open-loop run beside a closed-loop one, else ``A/B``."""
        return "open/closed" if self.open_closed else "A/B"

    @property
    def label_a(self) -> str:
        """A's column header: ``A`` or, in an open/closed pair, ``A (open loop)`` …"""
        return f"A ({self.loop_a})" if self.open_closed else "A"

    @property
    def label_b(self) -> str:
        return f"B ({self.loop_b})" if self.open_closed else "B"

    def describe(self) -> str:
        """One line: which run is what, on what, and whether the pipelines agree."""
        if not self.open_closed:
            return f"A/B of {self.loop_a} runs of {self.source}"
        same = (
            "the same pipeline"
            if not self.pipeline_differences
            else "DIFFERENT pipelines (" + "; ".join(self.pipeline_differences) + ")"
        )
        return (
            f"open loop beside closed loop: A is {self.loop_a}, B is {self.loop_b}, "
            f"{same}, on {self.source}"
        )

    def to_dict(self) -> dict[str, Any]:
        return {
            "kind": self.kind,
            "a": self.loop_a,
            "b": self.loop_b,
            "source": self.source,
            "same_pipeline": not self.pipeline_differences,
            "pipeline_differences": list(self.pipeline_differences),
            "notes": list(self.notes),
        }


def run_loop(run: Run) -> str:
    """``"closed loop"`` for a run of the closed-loop mode, else ``"open loop"``."""
    m = run.manifest
    return CLOSED_LOOP if m.closed_loop or m.pipeline.mode_manager == "closed_loop" else OPEN_LOOP


def _scenario_of_closed(run: Run) -> Mapping[str, Any] | None:
    closed = run.manifest.closed_loop
    if closed and run.manifest.log.format == "scenario":
        return closed
    return None


def _scenario_text(name: Any, seed: Any, duration_s: Any) -> str:
    return f"scenario {name} seed {seed} duration {duration_s} s"


def _log_hash(run: Run) -> str:
    """What the run was made from: the log's sha256, or for a closed-loop run of a scenario the
    scenario, its seed and duration (two such runs saw the same world if these agree)."""
    closed = _scenario_of_closed(run)
    if closed is not None:
        return (
            _scenario_text(closed.get("scenario"), closed.get("seed"), closed.get("duration_s"))
            + f" agents {closed.get('agents')}"
        )
    sha = run.manifest.log.sha256 or ""
    if not sha:
        msg = (
            f"{run.path / 'manifest.json'} records no log sha256; cannot check the runs share a log"
        )
        raise ConfigError(msg)
    return sha


def _same_loop(ra: Run, rb: Run) -> str:
    sha_a, sha_b = _log_hash(ra), _log_hash(rb)
    if sha_a != sha_b:
        msg = (
            f"runs replayed different logs: A {ra.path / 'manifest.json'} has {sha_a} "
            f"({ra.manifest.log.path}), B {rb.path / 'manifest.json'} has {sha_b} "
            f"({rb.manifest.log.path}); compare runs of the same log (or scenario and seed)"
        )
        raise ConfigError(msg)
    return sha_a


def _open_closed(open_run: Run, closed_run: Run, *, open_is: str) -> tuple[str, tuple[str, ...]]:
    """The shared source of an open-loop and a closed-loop run, and the notes on it."""
    closed_is = "B" if open_is == "A" else "A"
    closed = _scenario_of_closed(closed_run)
    if closed is None:  # a closed loop on a recorded log: the same log as the replay
        sha_o, sha_c = open_run.manifest.log.sha256 or "", closed_run.manifest.log.sha256 or ""
        if not sha_o or sha_o != sha_c:
            msg = (
                f"the open-loop run {open_is} ({open_run.path}) replayed {open_run.manifest.log.path}"
                f" (sha256 {sha_o or 'not recorded'}), the closed-loop run {closed_is} "
                f"({closed_run.path}) drove {closed_run.manifest.log.path} (sha256 "
                f"{sha_c or 'not recorded'}): not the same log; put side by side an open-loop and "
                "a closed-loop run of the same log"
            )
            raise ConfigError(msg)
        return sha_o, (f"closed loop agents: {closed_run.manifest.closed_loop.get('agents')}",)
    name, seed, dur = closed.get("scenario"), closed.get("seed"), closed.get("duration_s")
    closed_text = _scenario_text(name, seed, dur)
    recorded = open_run.manifest.log.scenario
    if not recorded:
        msg = (
            f"the closed-loop run {closed_is} ({closed_run.path}) ran {closed_text}; the "
            f"open-loop run {open_is} ({open_run.path}) replayed {open_run.manifest.log.path}, "
            "which records no scenario (it is not a `redrive synth` log, or one synthesized "
            "before redrive recorded the scenario in it: synthesize it again and re-run): "
            "cannot tell they saw the same situation"
        )
        raise ConfigError(msg)
    wanted = {"scenario": name, "seed": seed, "duration_s": dur}
    have = {
        "scenario": recorded.get("name"),
        "seed": recorded.get("seed"),
        "duration_s": recorded.get("duration_s"),
    }
    differ = [k for k in wanted if not _equal(wanted[k], have[k])]
    if differ:
        fix = {"seed": f"--seed {have['seed']}", "duration_s": f"--duration {have['duration_s']}"}
        how = " ".join(fix[k] for k in differ if k in fix)
        advice = (
            f"run the closed loop with {how}"
            if "scenario" not in differ
            else f"run the closed loop on scenario {have['scenario']}"
        )
        msg = (
            f"not the same situation ({', '.join(differ)} differ): the open-loop run {open_is} "
            f"({open_run.path}) replayed a log of "
            f"{_scenario_text(have['scenario'], have['seed'], have['duration_s'])} "
            f"({open_run.manifest.log.path}), the closed-loop run {closed_is} "
            f"({closed_run.path}) ran {closed_text}; {advice}"
        )
        raise ConfigError(msg)
    agents = closed.get("agents")
    note = (
        f"closed loop agents: {agents}"
        + (" (they react to the driven ego; in the log they follow their script)"
           if agents == "reactive" else " (as scripted, as in the log)")
    )  # fmt: skip
    return closed_text, (note,)


def _equal(x: Any, y: Any) -> bool:
    if isinstance(x, int | float) and isinstance(y, int | float):
        return float(x) == float(y)
    return bool(x == y)


def _pipeline_differences(ra: Run, rb: Run) -> tuple[str, ...]:
    """How B's pipeline differs from A's: algorithms (name, stage, role, class, version and
    configuration hash) and the pipeline seed."""
    algos_a = {a.name: a for a in ra.manifest.algorithms}
    algos_b = {b.name: b for b in rb.manifest.algorithms}
    out: list[str] = []
    for name in [*algos_a, *(n for n in algos_b if n not in algos_a)]:
        a, b = algos_a.get(name), algos_b.get(name)
        if a is None or b is None:
            out.append(f"{name} only in {'A' if b is None else 'B'}")
            continue
        for what, va, vb in (
            ("stage", a.stage, b.stage),
            ("role", a.role.value, b.role.value),
            ("class", a.class_name, b.class_name),
            ("version", a.version, b.version),
        ):
            if va != vb:
                out.append(f"{name}: {what} {va} in A, {vb} in B")
        if a.config_hash != b.config_hash:
            keys = sorted(set(a.config) | set(b.config))
            diff = [
                f"{k} {a.config.get(k, '—')!r} → {b.config.get(k, '—')!r}"
                for k in keys
                if a.config.get(k) != b.config.get(k)
            ]
            out.append(f"{name}: configuration differs ({', '.join(diff) or 'config hash'})")
    if list(algos_a) != [b for b in algos_b if b in algos_a] and not out:
        out.append("the algorithms run in another order")
    if ra.manifest.seed != rb.manifest.seed:
        out.append(f"pipeline seed {ra.manifest.seed} in A, {rb.manifest.seed} in B")
    return tuple(out)


def pair_runs(ra: Run, rb: Run) -> Pairing:
    """The pairing of ``ra`` (A) and ``rb`` (B); see the module doc.

    Raises:
        ConfigError: they were not made from the same log or situation (the message names both,
            what differs and what to run), or a run records no log hash.
    """
    loop_a, loop_b = run_loop(ra), run_loop(rb)
    if loop_a == loop_b:
        return Pairing(
            open_closed=False,
            loop_a=loop_a,
            loop_b=loop_b,
            source=_same_loop(ra, rb),
            pipeline_differences=_pipeline_differences(ra, rb),
        )
    if loop_a == OPEN_LOOP:
        source, notes = _open_closed(ra, rb, open_is="A")
    else:
        source, notes = _open_closed(rb, ra, open_is="B")
    return Pairing(
        open_closed=True,
        loop_a=loop_a,
        loop_b=loop_b,
        source=source,
        pipeline_differences=_pipeline_differences(ra, rb),
        notes=notes,
    )
