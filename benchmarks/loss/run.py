"""Running the benchmark: one configuration in fresh processes, and every configuration in turn."""

from __future__ import annotations

import logging
import multiprocessing
import os
import queue
import tempfile
import time
import uuid
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from benchmarks.loss.child import _child_main
from benchmarks.loss.machine import _machine, wakeup_probe
from benchmarks.loss.measures import measure_stream
from benchmarks.loss.process import _START_TIMEOUT_S, _RunSpec
from benchmarks.loss.results import ConfigResult, LossBenchResult
from benchmarks.loss.streams import _NS, CHAINS, DRAIN_S, QUEUE_DEPTH, SLOTS, STREAMS
from redrive.errors import TransportError

__all__ = ["bench_loss", "run_configuration"]

logger = logging.getLogger(__name__)

_JOIN_TIMEOUT_S = 10.0


def _await(
    status: Any,
    procs: dict[str, Any],
    want: set[str],
    kind: str,
    *,
    timeout_s: float,
    tick: Callable[[], None] | None = None,
) -> None:
    """Wait until every role in ``want`` reported ``kind``; TransportError on error/death/timeout."""
    deadline = time.monotonic() + timeout_s
    pending = set(want)
    while pending:
        try:
            item = status.get(timeout=0.5)
        except queue.Empty:
            if tick is not None:
                tick()
            for role, proc in sorted(procs.items()):
                code = proc.exitcode
                if code is not None and (code != 0 or role in pending):
                    msg = f"the {role} process exited (code {code}) before it was {kind}"
                    raise TransportError(msg) from None
            if time.monotonic() > deadline:
                msg = f"timed out after {timeout_s:.0f} s waiting for {', '.join(sorted(pending))}"
                raise TransportError(msg) from None
            continue
        if item[0] == "error":
            msg = f"the {item[1]} process failed: {item[2]}"
            raise TransportError(msg)
        if item[0] == kind:
            pending.discard(item[1])


_PRIVATE = {"collector-legacy": ("pipe_send",), "bridge-legacy": ("pipe_recv", "queue"),
            "core-legacy": ("queue",)}  # fmt: skip


def _role_ipc(ipc: dict[str, Any], role: str) -> dict[str, Any]:
    """What ``role`` gets: each pipe end and the queue go only to their users (a pipe whose other
    end is held by a bystander never reports EOF or a broken pipe when its peer dies)."""
    private = {k for keys in _PRIVATE.values() for k in keys}
    return {k: v for k, v in ipc.items() if k not in private or k in _PRIVATE.get(role, ())}


def _stop(procs: dict[str, Any]) -> None:
    for proc in procs.values():
        proc.join(_JOIN_TIMEOUT_S)
        if proc.is_alive():
            logger.warning("%s did not exit; terminating it", proc.name)
            proc.terminate()
            proc.join(5.0)
        if proc.is_alive():
            proc.kill()
            proc.join(5.0)


def run_configuration(
    chain: str,
    rate_factor: float,
    *,
    seconds: float,
    slots: int = SLOTS,
    progress: Callable[[str], None] | None = None,
) -> ConfigResult:
    """Run ``chain`` at ``rate_factor`` × the sensor rates for ``seconds`` in fresh processes.

    Raises:
        TransportError: a process failed, died or hung (all of them are stopped first).
    """
    if chain not in CHAINS:
        msg = f"unknown chain {chain!r}; known: {', '.join(CHAINS)}"
        raise TransportError(msg)
    ctx = multiprocessing.get_context("spawn")
    tag = f"loss-{os.getpid()}-{uuid.uuid4().hex[:8]}"
    names = tuple(f"{tag}.{st.name}" for st in STREAMS)
    legacy = chain == "legacy"
    label = f"{chain} {rate_factor:g}×"
    with tempfile.TemporaryDirectory(prefix="redrive-loss-") as tmp:
        spec = _RunSpec(
            chain=chain, rate_factor=rate_factor, seconds=seconds, names=names, out_dir=tmp,
            slots=slots,
        )  # fmt: skip
        ipc: dict[str, Any] = {
            "status": ctx.Queue(),
            "go": ctx.Event(),
            "stop": ctx.Event(),
            "collector_done": ctx.Event(),
            "t0": ctx.RawValue("q", 0),
            "last_sent": ctx.RawArray("q", len(STREAMS)),
        }
        roles = ["core-redrive", "collector-redrive"]
        if legacy:
            ipc["pipe_recv"], ipc["pipe_send"] = ctx.Pipe(duplex=False)
            ipc["queue"] = ctx.Queue(maxsize=QUEUE_DEPTH)
            roles = ["core-legacy", "bridge-legacy", "collector-legacy"]
        else:
            roles.reverse()  # the collector creates the streams the core attaches to
        procs: dict[str, Any] = {}
        try:
            for role in roles:
                short = role.split("-", 1)[0]
                proc = ctx.Process(
                    target=_child_main,
                    args=(role, spec, _role_ipc(ipc, role)),
                    name=f"loss-{role}",
                    daemon=True,
                )
                proc.start()
                procs[short] = proc
                _await(ipc["status"], procs, {short}, "ready", timeout_s=_START_TIMEOUT_S)
            if legacy:  # the children hold the pipe now: EOF when one side dies
                ipc["pipe_recv"].close()
                ipc["pipe_send"].close()
            t0 = time.monotonic_ns() + 500_000_000
            ipc["t0"].value = t0
            ipc["go"].set()

            def tick() -> None:
                if progress is not None:
                    now = max(0.0, (time.monotonic_ns() - t0) / _NS)
                    progress(f"{label}: {min(now, seconds):.0f}/{seconds:g} s")

            _await(
                ipc["status"], procs, set(procs) - {"bridge"}, "done",
                timeout_s=seconds + DRAIN_S + 120.0, tick=tick,
            )  # fmt: skip
            coll = np.load(Path(tmp) / "collector.npz")
            core = np.load(Path(tmp) / "core.npz")
        finally:
            ipc["stop"].set()
            ipc["go"].set()
            _stop(procs)
            if not legacy:
                from redrive.transport import remove_stale

                for name in names:
                    remove_stale(name)
            for q in (ipc["status"], ipc.get("queue")):
                if q is not None:
                    q.close()
                    q.cancel_join_thread()
        t0 = int(coll["t0"])
        dues = spec.dues(t0)
        streams = tuple(
            measure_stream(
                st.name,
                rate_hz=spec.rate(s),
                payload_bytes=st.payload_bytes,
                due_ns=dues[s],
                produced_ns=coll[f"produced_{s}"],
                recv_ns=core[f"recv_{s}"],
                t0_ns=t0,
                seconds=seconds,
                transport_dropped=int(core["dropped"][s]),
                corrupt=int(core["corrupt"][s]),
            )
            for s, st in enumerate(STREAMS)
        )
    return ConfigResult(chain=chain, rate_factor=rate_factor, seconds=seconds, streams=streams)


def bench_loss(
    *,
    seconds: float = 1800.0,
    rate_factors: Sequence[float] = (1.0, 10.0),
    chains: Sequence[str] = ("legacy", "redrive"),
    slots: int = SLOTS,
    progress: Callable[[str], None] | None = None,
) -> LossBenchResult:
    """Every chain at every rate factor, one after the other, ``seconds`` each. A configuration
    that fails is reported with its ``error``; the others still run."""
    if seconds <= 0 or not rate_factors or any(f <= 0 for f in rate_factors) or slots < 3:
        msg = (
            "need seconds > 0, rate factors > 0 and at least 3 slots "
            f"(got {seconds}, {list(rate_factors)}, {slots})"
        )
        raise TransportError(msg)
    unknown = [c for c in chains if c not in CHAINS]
    if unknown or not chains:
        msg = f"unknown chain(s) {', '.join(unknown) or '(none given)'}; known: {', '.join(CHAINS)}"
        raise TransportError(msg)
    machine = _machine()
    probe = wakeup_probe(min(3.0, seconds / 10))
    configs: list[ConfigResult] = []
    for factor in rate_factors:
        for chain in chains:
            logger.info("loss benchmark: %s at %g× for %g s", chain, factor, seconds)
            try:
                configs.append(
                    run_configuration(
                        chain, factor, seconds=seconds, slots=slots, progress=progress
                    )
                )
            except TransportError as err:
                logger.warning("loss benchmark: %s at %g× failed: %s", chain, factor, err)
                configs.append(
                    ConfigResult(
                        chain=chain, rate_factor=factor, seconds=seconds, streams=(),
                        error=str(err),
                    )
                )  # fmt: skip
    return LossBenchResult(
        seconds=seconds, configs=tuple(configs), machine=machine, slots=slots, wakeup=probe
    )
