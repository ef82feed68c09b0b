"""``python -m benchmarks record``: redrive's recorder against ``rosbag record`` on the same playback.

One ROS 1 master (``rosmaster --core`` on a free port), one ``rosbag play -l -r RATE --pause`` of a
bag, and side by side the real ``rosbag record`` (C++, started through its Python wrapper) and
``redrive live TOPICS --record`` (record-only: no pipeline; its scrapers are child processes).
Once both have connected to every topic of the player, the playback is un-paused for the window,
then paused again (through ``rosbag play``'s own ``pause_playback`` service), so both recorders are
offered exactly the same messages. The CPU time of each one's process tree (the process and every
descendant, from psutil: ``/proc/PID/stat``) is read when the window opens and after the pause
(once both had a moment to write what they hold); then both get SIGINT, as Ctrl-C would, and the
messages are counted per topic from the files they wrote.
"""

from __future__ import annotations

import contextlib
import os
import shutil
import signal
import socket
import struct
import subprocess
import sys
import tempfile
import threading
import time
import xmlrpc.client
from collections.abc import Callable, Iterator, Sequence
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

from redrive.errors import ConfigError, TransportError
from redrive.testing.processes import stop_group, wait_group
from redrive.testing.ros1 import MasterError, start_master

__all__ = [
    "DEFAULT_RATE",
    "KITTI_BAG",
    "TARGET_CPU_RATIO",
    "RecordResult",
    "TopicCount",
    "bench_record",
    "compare_counts",
    "cpu_by_process",
    "tree_cpu_s",
]

#: the bag of ``../shared/data`` (3 KITTI frames, 1.04 s): its 3 messages per topic come
#: once every 1.04 s / rate (rosbag play -l waits out the bag's length between loops)
KITTI_BAG = Path("rosbag1_recorded_here/kitti_3frames_rosbag_record_lz4.bag")
#: ``rosbag play -r`` of it: ≈ 33 messages/s per topic (≥ 30 Hz, issue 22)
DEFAULT_RATE = 14.0
#: redrive's process tree may use at most this much of ``rosbag record``'s CPU time (issue 22)
TARGET_CPU_RATIO = 1.0
#: ``redrive live --compression`` → ``rosbag record``'s option for it (it has no zstd: with
#: ``zstd`` it writes uncompressed, and the comparison says what zstd costs redrive)
_ROSBAG_COMPRESSION: dict[str, list[str]] = {"none": [], "lz4": ["--lz4"], "zstd": []}
_REFERENCE_NODE = "/bench_reference_recorder"
_PLAYER_NODE = "/bench_player"


@dataclass(frozen=True, slots=True)
class TopicCount:
    """One topic: messages (and their bytes) in ``rosbag record``'s bag and in redrive's file."""

    topic: str
    reference: int
    redrive: int
    reference_bytes: int = 0
    redrive_bytes: int = 0

    @property
    def lost(self) -> int:
        """Messages ``rosbag record`` recorded that redrive did not (never negative)."""
        return max(self.reference - self.redrive, 0)


def compare_counts(
    reference: dict[str, tuple[int, int]], redrive: dict[str, tuple[int, int]]
) -> list[TopicCount]:
    """Topic → (messages, bytes) of each recorder → a row per topic either recorded, by name."""
    return [
        TopicCount(
            topic=topic,
            reference=reference.get(topic, (0, 0))[0],
            redrive=redrive.get(topic, (0, 0))[0],
            reference_bytes=reference.get(topic, (0, 0))[1],
            redrive_bytes=redrive.get(topic, (0, 0))[1],
        )
        for topic in sorted(set(reference) | set(redrive))
    ]


def tree_cpu_s(pid: int) -> float:
    """User + system CPU seconds of process ``pid`` and all its living descendants, plus what its
    children that exited and were waited for used (0 when the process is gone)."""
    import psutil

    try:
        root = psutil.Process(pid)
        procs = [root, *root.children(recursive=True)]
    except psutil.NoSuchProcess:
        return 0.0
    total = 0.0
    for proc in procs:
        with contextlib.suppress(psutil.NoSuchProcess, psutil.AccessDenied):
            t = proc.cpu_times()
            total += t.user + t.system
            if proc is root:
                total += t.children_user + t.children_system
    return total


def cpu_by_process(pid: int) -> dict[str, float]:
    """CPU seconds of each living process of ``pid``'s tree, by what it is: ``recorder`` (the
    process ``pid``, with what its waited-for children used), ``scraper TOPIC``, else its name."""
    import psutil

    out: dict[str, float] = {}
    try:
        root = psutil.Process(pid)
        procs = [root, *root.children(recursive=True)]
    except psutil.NoSuchProcess:
        return out
    for proc in procs:
        with contextlib.suppress(psutil.NoSuchProcess, psutil.AccessDenied):
            t = proc.cpu_times()
            used = t.user + t.system
            if proc is root:
                label, used = "recorder", used + t.children_user + t.children_system
            else:
                argv = proc.cmdline()
                topic = argv[argv.index("--topic") + 1] if "--topic" in argv[:-1] else None
                if "redrive.live.ros2_scraper" in argv:  # one process for every ROS 2 topic
                    topic = "(ROS 2)"
                label = f"scraper {topic}" if topic else proc.name()
            out[label] = out.get(label, 0.0) + used
    return out


@dataclass(slots=True)
class RecordResult:
    """One run: per-topic counts, CPU seconds of each recorder's tree over the window (and over
    its whole life up to the end of the window), the machine's load."""

    bag: str
    rate: float
    compression: str
    window_s: float
    topics: list[TopicCount]
    reference_cpu_s: float
    redrive_cpu_s: float
    reference_cpu_total_s: float
    redrive_cpu_total_s: float
    redrive_processes: int
    #: redrive's CPU seconds in the window by process (recorder, each scraper)
    redrive_cpu_by_process: dict[str, float]
    cpus: int
    load_before: tuple[float, float, float]
    load_after: tuple[float, float, float]
    notes: list[str] = field(default_factory=list)
    #: chunks of redrive's file by compression ("none" included): with compression, the chunks
    #: the compressor could not keep up with are written uncompressed
    redrive_chunks: dict[str, int] = field(default_factory=dict)

    @property
    def lost(self) -> int:
        return sum(t.lost for t in self.topics)

    @property
    def cpu_ratio(self) -> float:
        """redrive's CPU over ``rosbag record``'s, in the window (inf when the latter used none)."""
        if self.reference_cpu_s <= 0:
            return float("inf")
        return self.redrive_cpu_s / self.reference_cpu_s

    @property
    def cpu_per_mb(self) -> tuple[float, float]:
        """CPU milliseconds per MB recorded: (rosbag record, redrive) — fair when one of them
        recorded fewer messages than the other (a loaded machine)."""
        ref_mb = sum(t.reference_bytes for t in self.topics) / 1e6
        ours_mb = sum(t.redrive_bytes for t in self.topics) / 1e6
        return (
            1e3 * self.reference_cpu_s / ref_mb if ref_mb else float("inf"),
            1e3 * self.redrive_cpu_s / ours_mb if ours_mb else float("inf"),
        )

    def hz(self, count: TopicCount) -> float:
        """Messages per second ``rosbag record`` recorded on a topic in the window."""
        return count.reference / self.window_s if self.window_s > 0 else 0.0

    def to_json(self) -> dict[str, Any]:
        out = asdict(self)
        out["topics"] = [dict(asdict(t), lost=t.lost) for t in self.topics]
        out["lost"] = self.lost
        out["cpu_ratio"] = self.cpu_ratio
        out["cpu_ms_per_mb"] = self.cpu_per_mb
        return out


# -- the ROS 1 side --------------------------------------------------------------------------


def _missing_tools() -> str | None:
    for tool in ("rosmaster", "rosbag"):
        if shutil.which(tool, path="/usr/bin:/bin") is None:
            return (
                f"`{tool}` is not installed: `python -m benchmarks record` needs Debian's ROS 1 "
                "(`make system-test-deps`, as root)"
            )
    return None


@contextlib.contextmanager
def _master(home: Path) -> Iterator[tuple[str, dict[str, str]]]:
    """A ``rosmaster --core`` of our own for the ``with`` block: its URI and its clients'
    environment; stopped with its whole process group at exit."""
    try:
        master = start_master(home, timeout_s=30.0)
    except MasterError as exc:
        raise TransportError(str(exc)) from None
    try:
        yield master.uri, master.env
    finally:
        master.stop()


def _outbound_connections(uri: str, node: str) -> int:
    """Subscriber connections node ``node`` has open (its ``getBusInfo``); 0 before it exists."""
    try:
        found: Any = xmlrpc.client.ServerProxy(uri).lookupNode("/bench", node)
        code, _, api = found
        if code != 1:
            return 0
        bus: Any = xmlrpc.client.ServerProxy(str(api)).getBusInfo("/bench")
        info = bus[2]
    except (OSError, xmlrpc.client.Error):
        return 0
    return sum(1 for c in info if c[2] == "o" and c[5])


def _set_paused(uri: str, *, paused: bool) -> None:
    """Call ``rosbag play``'s ``pause_playback`` (std_srvs/SetBool) over TCPROS, stdlib only."""
    service = f"{_PLAYER_NODE}/pause_playback"
    found: Any = xmlrpc.client.ServerProxy(uri).lookupService("/bench", service)
    code, status, address = found
    if code != 1:
        msg = f"{service}: {status}"
        raise TransportError(msg)
    host, port = str(address).removeprefix("rosrpc://").rstrip("/").rsplit(":", 1)
    fields = ["callerid=/bench", f"service={service}", "md5sum=*", "persistent=0"]
    blob = b"".join(struct.pack("<I", len(f)) + f.encode() for f in fields)
    with socket.create_connection((host, int(port)), timeout=10) as sock:
        sock.sendall(struct.pack("<I", len(blob)) + blob)
        (size,) = struct.unpack("<I", _recv(sock, 4))
        _recv(sock, size)  # the server's connection header
        sock.sendall(struct.pack("<IB", 1, int(paused)))
        if _recv(sock, 1) != b"\x01":
            msg = f"{service} refused the call"
            raise TransportError(msg)


def _recv(sock: socket.socket, size: int) -> bytes:
    out = b""
    while len(out) < size:
        chunk = sock.recv(size - len(out))
        if not chunk:
            msg = "rosbag play's pause service closed the connection"
            raise TransportError(msg)
        out += chunk
    return out


def _bag_topics(bag: Path) -> list[str]:
    from rosbags.rosbag1 import Reader

    with Reader(bag) as reader:
        return sorted(c.topic for c in reader.connections)


def _count_bag(path: Path) -> dict[str, tuple[int, int]]:
    from rosbags.rosbag1 import Reader

    out: dict[str, tuple[int, int]] = {}
    with Reader(path) as reader:
        for conn, _, raw in reader.messages():
            n, size = out.get(conn.topic, (0, 0))
            out[conn.topic] = (n + 1, size + len(raw))
    return out


def _chunks(path: Path) -> dict[str, int]:
    from mcap.reader import make_reader

    out: dict[str, int] = {}
    with path.open("rb") as fh:
        summary = make_reader(fh).get_summary()
    for index in summary.chunk_indexes if summary is not None else ():
        kind = index.compression or "none"
        out[kind] = out.get(kind, 0) + 1
    return out


def _count_mcap(path: Path) -> dict[str, tuple[int, int]]:
    from redrive.io import open_log

    out: dict[str, tuple[int, int]] = {}
    with open_log(path) as log:
        for m in log.messages():
            n, size = out.get(m.topic, (0, 0))
            out[m.topic] = (n + 1, size + len(m.raw))
    return out


class _Lines:
    """Collects a process's text output in a thread (so the pipe never fills)."""

    def __init__(self, stream: Any) -> None:
        self.lines: list[str] = []
        self._thread = threading.Thread(target=self._drain, args=(stream,), daemon=True)
        self._thread.start()

    def _drain(self, stream: Any) -> None:
        for line in stream:
            self.lines.append(line)

    def wait_for(self, prefix: str, proc: subprocess.Popen[str], timeout_s: float) -> None:
        deadline = time.monotonic() + timeout_s
        while not any(line.startswith(prefix) for line in self.lines):
            if proc.poll() is not None or time.monotonic() > deadline:
                text = "".join(self.lines)[-2000:]
                msg = f"redrive live did not start recording: {text or 'no output'}"
                raise TransportError(msg)
            time.sleep(0.05)

    @property
    def text(self) -> str:
        self._thread.join(timeout=5)
        return "".join(self.lines)


def bench_record(
    *,
    data_dir: Path,
    rate: float = DEFAULT_RATE,
    window_s: float = 20.0,
    bag: Path = KITTI_BAG,
    topics: Sequence[str] | None = None,
    compression: str = "none",
    settle_s: float = 1.0,
    workdir: Path | None = None,
    progress: Callable[[str], None] | None = None,
) -> RecordResult:
    """Record ``window_s`` seconds of a looped playback of ``data_dir / bag`` at ``rate`` with both,
    with chunk ``compression`` (``none``, ``lz4``; ``zstd``: redrive only). The CPU time is read
    ``settle_s`` after the playback paused (both have written what they received by then).

    Raises:
        ConfigError: ROS 1 is not installed, the bag is missing or a number is out of range.
        TransportError: a process did not start or connect in time.
    """
    say = progress or (lambda _text: None)
    missing = _missing_tools()
    if missing is not None:
        raise ConfigError(missing)
    bag_path = data_dir / bag
    if not bag_path.is_file():
        msg = f"{bag_path} is missing: give --data the folder that holds {bag}"
        raise ConfigError(msg)
    if rate <= 0 or window_s <= 0:
        msg = f"--rate {rate:g} and --duration {window_s:g} must be more than 0"
        raise ConfigError(msg)
    if compression not in _ROSBAG_COMPRESSION:
        msg = f"--compression {compression!r}: one of {', '.join(_ROSBAG_COMPRESSION)}"
        raise ConfigError(msg)
    plan = _Plan(
        bag=bag_path,
        rate=rate,
        window_s=window_s,
        topics=list(topics) if topics else _bag_topics(bag_path),
        compression=compression,
        settle_s=settle_s,
    )
    if workdir is not None:
        return _run(plan, workdir, say)
    with tempfile.TemporaryDirectory(prefix="bench-record-") as tmp:
        return _run(plan, Path(tmp), say)


@dataclass(frozen=True, slots=True)
class _Plan:
    bag: Path
    rate: float
    window_s: float
    topics: list[str]
    compression: str
    settle_s: float


def _run(plan: _Plan, work: Path, say: Callable[[str], None]) -> RecordResult:
    bag, rate, window_s, topics = plan.bag, plan.rate, plan.window_s, plan.topics
    load_before = os.getloadavg()
    notes: list[str] = []
    with _master(work / "ros") as (uri, env):
        say("starting rosbag play (paused), rosbag record and redrive live")
        player = subprocess.Popen(
            ["rosbag", "play", "-l", "--pause", "-r", f"{rate:g}", str(bag),
             f"__name:={_PLAYER_NODE[1:]}"],
            env=env, stdin=subprocess.DEVNULL, stdout=subprocess.DEVNULL,
            stderr=subprocess.DEVNULL, start_new_session=True,
        )  # fmt: skip
        reference = subprocess.Popen(
            ["rosbag", "record", *_ROSBAG_COMPRESSION[plan.compression],
             "-O", str(work / "reference.bag"), *topics,
             f"__name:={_REFERENCE_NODE[1:]}"],
            env=env, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL,
            start_new_session=True,
        )  # fmt: skip
        ours = subprocess.Popen(
            [sys.executable, "-m", "redrive", "live", "--master", uri, *topics,
             "--record", str(work / "redrive.mcap"), "--compression", plan.compression,
             "--idle-timeout", "3600", "--wait", "60"],
            env=dict(os.environ, ROS_MASTER_URI=uri), stdin=subprocess.DEVNULL,
            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, start_new_session=True,
        )  # fmt: skip
        assert ours.stdout is not None
        assert ours.stderr is not None
        out_lines, err_lines = _Lines(ours.stdout), _Lines(ours.stderr)
        try:
            err_lines.wait_for("live: recording", ours, timeout_s=90)
            deadline = time.monotonic() + 60
            while _outbound_connections(uri, _PLAYER_NODE) < 2 * len(topics):
                if time.monotonic() > deadline or player.poll() is not None:
                    msg = "the recorders did not connect to every topic of rosbag play within 60 s"
                    raise TransportError(msg)
                time.sleep(0.05)
            say(f"recording {window_s:g} s of playback at {rate:g}x")
            cpu0 = (tree_cpu_s(reference.pid), tree_cpu_s(ours.pid))
            parts0 = cpu_by_process(ours.pid)
            start = time.monotonic()
            _set_paused(uri, paused=False)
            time.sleep(max(window_s - (time.monotonic() - start), 0.0))
            _set_paused(uri, paused=True)
            window = time.monotonic() - start
            time.sleep(plan.settle_s)  # both write what they still hold
            cpu1 = (tree_cpu_s(reference.pid), tree_cpu_s(ours.pid))
            parts = {k: v - parts0.get(k, 0.0) for k, v in cpu_by_process(ours.pid).items()}
            import psutil

            processes = 0
            with contextlib.suppress(psutil.NoSuchProcess):
                processes = 1 + len(psutil.Process(ours.pid).children(recursive=True))
            say("stopping both with SIGINT")
            for proc in (reference, ours):  # Ctrl-C to both at once (once: a second one
                with contextlib.suppress(ProcessLookupError):  # interrupts the closing)
                    os.killpg(proc.pid, signal.SIGINT)
            # the whole group: rosbag record's Python wrapper leaves at once, its C++ recorder
            # closes the bag after it
            for proc, wait_s in ((reference, 30.0), (ours, 60.0)):
                wait_group(proc, wait_s)
        finally:
            for proc in (reference, ours, player):
                stop_group(proc, wait_s=10)
        if ours.returncode != 0:
            msg = f"redrive live exited with {ours.returncode}: {err_lines.text[-2000:]}"
            raise TransportError(msg)
        if reference.returncode not in (0, -signal.SIGINT):
            notes.append(f"rosbag record exited with {reference.returncode}")
        (work / "redrive-live.txt").write_text(out_lines.text + err_lines.text)
    say("counting the recorded messages")
    counts = compare_counts(_count_bag(work / "reference.bag"), _count_mcap(work / "redrive.mcap"))
    return RecordResult(
        bag=str(bag),
        rate=rate,
        compression=plan.compression,
        window_s=window,
        topics=counts,
        reference_cpu_s=cpu1[0] - cpu0[0],
        redrive_cpu_s=cpu1[1] - cpu0[1],
        reference_cpu_total_s=cpu1[0],
        redrive_cpu_total_s=cpu1[1],
        redrive_processes=processes,
        redrive_cpu_by_process=parts,
        cpus=os.cpu_count() or 1,
        load_before=load_before,
        load_after=os.getloadavg(),
        notes=notes,
        redrive_chunks=_chunks(work / "redrive.mcap"),
    )
