"""``python -m benchmarks serve``: ``redrive serve`` of the demo log at 1× to a client on loopback.

The demo log (``redrive synth urban --duration 20``) is made once, unless a log is given.  What
the server will send is counted first from the same stream (:func:`~redrive.interop.stream.
open_scene_stream`: every message per channel, in this process, not timed).  Then ``redrive
serve LOG --port 0 --rate R`` runs as a child process; a WebSocket client (``websockets``, in
this process, doing nothing but note what arrives) subscribes to every channel — which starts
the playback — and receives until everything arrived, or the player said it ended and nothing
came for a few seconds, or the deadline.

Reported per channel: messages sent (the stream's count) and received; dropped = sent −
received (frames: on the cloud and image channels); lag = (receive wall time − log time) minus
its smallest value over the run, p50 / p99 / max (how far behind the log's own pacing a message
arrived); the server process's CPU seconds over the playback (``/proc/PID/stat``) and the
client's; the load average before and after (2 cores are shared here).
"""

from __future__ import annotations

import asyncio
import json
import os
import re
import signal
import struct
import subprocess
import sys
import tempfile
import time
from collections import Counter
from collections.abc import Callable
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any

import numpy as np

from redrive.errors import ConfigError

__all__ = ["ServeBenchResult", "bench_serve", "make_demo_log"]

_SUBPROTOCOL = "foxglove.sdk.v1"
_MESSAGE_DATA, _PLAYBACK_STATE, _ENDED = 1, 5, 3
#: after the player said it ended: how long nothing may arrive before the client stops
_QUIET_S = 3.0
_FRAME_SCHEMAS = frozenset(
    {
        "sensor_msgs/msg/PointCloud2",
        "sensor_msgs/msg/Image",
        "sensor_msgs/msg/CompressedImage",
        "foxglove.PointCloud",
        "foxglove.CompressedImage",
    }
)


@dataclass(frozen=True, slots=True, kw_only=True)
class ChannelCount:
    """One channel: its topic and schema, messages the stream holds and messages received."""

    topic: str
    schema: str
    sent: int
    received: int

    @property
    def dropped(self) -> int:
        return self.sent - self.received


@dataclass(frozen=True, slots=True, kw_only=True)
class ServeBenchResult:
    """One ``bench_serve`` run (see the module text); times in seconds unless named ``_ms``."""

    log: Path
    log_span_s: float
    rate: float
    channels: tuple[ChannelCount, ...]
    server_sent: int | None  # what ``redrive serve`` said it sent when stopped
    play_wall_s: float
    lag_p50_ms: float
    lag_p99_ms: float
    lag_max_ms: float
    server_cpu_s: float
    client_cpu_s: float
    load_before: float
    load_after: float

    @property
    def sent(self) -> int:
        return sum(c.sent for c in self.channels)

    @property
    def received(self) -> int:
        return sum(c.received for c in self.channels)

    @property
    def dropped(self) -> int:
        return self.sent - self.received

    @property
    def dropped_frames(self) -> int:
        """Messages missing on the LiDAR and camera channels (raw and converted)."""
        return sum(c.dropped for c in self.channels if c.schema in _FRAME_SCHEMAS)

    @property
    def frames(self) -> int:
        return sum(c.sent for c in self.channels if c.schema in _FRAME_SCHEMAS)

    @property
    def server_cpu_percent(self) -> float:
        """The server's CPU over the playback, percent of one core."""
        return 100.0 * self.server_cpu_s / self.play_wall_s if self.play_wall_s > 0 else 0.0

    def to_json(self) -> dict[str, Any]:
        out = asdict(self)
        out["log"] = str(self.log)
        out["channels"] = [asdict(c) | {"dropped": c.dropped} for c in self.channels]
        out.update(
            sent=self.sent,
            received=self.received,
            dropped=self.dropped,
            frames=self.frames,
            dropped_frames=self.dropped_frames,
            server_cpu_percent=self.server_cpu_percent,
            # the figures `python -m benchmarks all` puts in its summary (1.0: nothing dropped)
            received_ratio=self.received / self.sent if self.sent else 0.0,
            frames_received_ratio=(
                (self.frames - self.dropped_frames) / self.frames if self.frames else 0.0
            ),
            realtime_factor=self.log_span_s / self.play_wall_s if self.play_wall_s > 0 else 0.0,
        )
        return out


def make_demo_log(workdir: Path, *, duration_s: float = 20.0) -> Path:
    """What ``redrive synth urban -o workdir/urban.mcap --duration D`` writes; returns its path."""
    from redrive.sim.scenario import load_scenario
    from redrive.sim.synth import synthesize

    log = workdir / "urban.mcap"
    synthesize(load_scenario("urban"), log, duration_s=duration_s)
    return log


def _expected(log: Path) -> tuple[dict[str, int], dict[str, str], float]:
    """Messages per channel of ``redrive serve LOG``, each channel's schema, the log's span."""
    from redrive.interop.stream import open_scene_stream

    with open_scene_stream(log) as stream:
        counts = Counter(m.topic for m in stream.messages())
        schemas = {t: c.schema_name for t, c in stream.channels.items()}
        span_s = (stream.end_ns - stream.start_ns) / 1e9
    return {t: counts.get(t, 0) for t in schemas}, schemas, span_s


def _cpu_s(pid: int) -> float:
    """utime + stime of a process, seconds (0 when it is gone)."""
    try:
        with open(f"/proc/{pid}/stat", encoding="ascii") as f:
            fields = f.read().rsplit(")", 1)[1].split()
    except OSError:
        return 0.0
    return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")


def _load() -> float:
    with open("/proc/loadavg", encoding="ascii") as f:
        return float(f.read().split()[0])


@dataclass(slots=True)
class _Received:
    topics: list[str]
    log_ns: list[int]
    recv_ns: list[int]
    play_wall_s: float = 0.0
    server_cpu_s: float = 0.0


async def _client(
    url: str, *, expected_total: int, channels: int, pid: int, deadline_s: float
) -> _Received:
    import websockets
    from websockets.typing import Subprotocol

    got = _Received([], [], [])
    async with websockets.connect(
        url, subprotocols=[Subprotocol(_SUBPROTOCOL)], max_size=None, close_timeout=1
    ) as ws:
        by_id: dict[int, str] = {}
        while len(by_id) < channels:
            msg = json.loads(await asyncio.wait_for(ws.recv(), 30))
            if msg["op"] == "advertise":
                by_id.update({c["id"]: c["topic"] for c in msg["channels"]})
        subs = dict(enumerate(by_id))
        topic_of = {sub: by_id[channel] for sub, channel in subs.items()}
        cpu0 = _cpu_s(pid)
        start = time.monotonic()
        request = [{"id": s, "channelId": c} for s, c in subs.items()]
        await ws.send(json.dumps({"op": "subscribe", "subscriptions": request}))
        ended_at: float | None = None
        last = start
        while len(got.topics) < expected_total:
            now = time.monotonic()
            if now > deadline_s or (ended_at is not None and now - last > _QUIET_S):
                break
            try:
                frame = await asyncio.wait_for(ws.recv(), 0.5)
            except TimeoutError:
                continue
            if isinstance(frame, str):
                continue
            if frame[0] == _MESSAGE_DATA:
                sub, log_ns = struct.unpack_from("<IQ", frame, 1)
                got.recv_ns.append(time.time_ns())
                got.topics.append(topic_of[sub])
                got.log_ns.append(log_ns)
                last = time.monotonic()
            elif frame[0] == _PLAYBACK_STATE and frame[1] == _ENDED and ended_at is None:
                ended_at = time.monotonic()
        got.play_wall_s = last - start
        got.server_cpu_s = _cpu_s(pid) - cpu0
    return got


def bench_serve(
    *,
    log: Path | None = None,
    workdir: Path | None = None,
    duration_s: float = 20.0,
    rate: float = 1.0,
    progress: Callable[[str], None] | None = None,
) -> ServeBenchResult:
    """Serve ``log`` (the demo, made in ``workdir`` or a temporary directory, when None) with
    ``redrive serve --rate rate`` and receive it all on loopback (see the module text).

    Raises:
        ConfigError: the log is not there, or ``redrive serve`` did not start.
    """
    from redrive.interop import require_foxglove

    require_foxglove()
    say = progress or (lambda _text: None)
    with tempfile.TemporaryDirectory(prefix="redrive-bench-serve-") as tmp:
        if log is None:
            say(f"making the {duration_s:g}-s demo log")
            log = make_demo_log(workdir or Path(tmp), duration_s=duration_s)
        if not log.exists():
            msg = f"{log}: no such log; give a log file with --log (or none to make the demo)"
            raise ConfigError(msg)
        say("counting what the server will send")
        expected, schemas, span_s = _expected(log)
        say("serving")
        load_before = _load()
        argv = [sys.executable, "-m", "redrive", "serve", str(log), "--port", "0",
                "--rate", str(rate)]  # fmt: skip
        proc = subprocess.Popen(argv, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
        try:
            assert proc.stdout is not None
            line = proc.stdout.readline()
            found = re.search(r"ws://[^\s]+", line)
            if found is None:
                err = proc.stderr.read() if proc.stderr else ""
                msg = f"redrive serve {log} did not start: {line.strip()} {err.strip()[-500:]}"
                raise ConfigError(msg)
            cpu0 = time.process_time()
            got = asyncio.run(
                _client(
                    found[0],
                    expected_total=sum(expected.values()),
                    channels=len(schemas),
                    pid=proc.pid,
                    deadline_s=time.monotonic() + span_s / rate * 3 + 60,
                )
            )
            client_cpu_s = time.process_time() - cpu0
        finally:
            proc.send_signal(signal.SIGTERM)
            try:
                out, _ = proc.communicate(timeout=30)
            except subprocess.TimeoutExpired:
                proc.kill()
                out, _ = proc.communicate()
    stopped = re.search(r"stopped after (\d+) messages", out or "")
    counts = Counter(got.topics)
    lag = np.asarray(got.recv_ns, dtype=np.int64) - np.asarray(got.log_ns, dtype=np.int64)
    lag_ms = (lag - lag.min()) / 1e6 if lag.size else np.zeros(1)
    return ServeBenchResult(
        log=log,
        log_span_s=span_s,
        rate=rate,
        channels=tuple(
            ChannelCount(topic=t, schema=schemas[t], sent=expected[t], received=counts.get(t, 0))
            for t in sorted(expected)
        ),
        server_sent=int(stopped[1]) if stopped else None,
        play_wall_s=got.play_wall_s,
        lag_p50_ms=float(np.percentile(lag_ms, 50)),
        lag_p99_ms=float(np.percentile(lag_ms, 99)),
        lag_max_ms=float(lag_ms.max()),
        server_cpu_s=got.server_cpu_s,
        client_cpu_s=client_cpu_s,
        load_before=load_before,
        load_after=_load(),
    )
