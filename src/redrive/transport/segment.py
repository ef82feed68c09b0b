"""One shared-memory segment per stream: its file in /dev/shm, its layout, its owner.

Layout (all integers little-endian int64 "words"; a *line* is 8 words = 64 bytes, one cache line)::

    control block (page-aligned size)
      line 0   magic, version, n_slots, slot_stride, capacity, max_readers, policy, generation
      line 1   owner_pid, owner_start, created_ns, closed
      line 2   write_seq                                  (alone on its line: written per message)
      line 3   -, -, writer_waiting  (the first two unused: published is write_seq)
      lines    order[n_slots]: slot of message n at order[n % n_slots]
      lines    reader r (2 lines each): pid, start, state, policy, read_seq, pin, delivered,
               dropped | torn, lag_last_ns, lag_max_ns, lag_sum_ns, capture_lag_ns, waiting, -, -
    slot s at control + s * slot_stride (page-aligned), each:
      line 0   seq_begin                                   (own line)
      line 1   seq_end                                     (own line)
      line 2   stamp_ns, publish_ns, kind, nbytes, meta_len
      byte 256 .. 4096   meta (META_CAPACITY bytes)
      page 1 .. payload (capacity rounded up to whole pages)

The segment is ``/dev/shm/redrive.<name>``, created ``0600`` with ``O_EXCL`` by its writer and
pre-touched, and mapped populated by its readers (no page faults per message). A process is
identified by pid *and* its start time (``/proc/PID/stat`` field 22), so a recycled pid is not
mistaken for a live owner. A segment whose owner is gone is *stale*: :func:`remove_stale` unlinks
it (a writer does so for its own name at start).
"""

from __future__ import annotations

import contextlib
import logging
import mmap
import os
import re
import secrets
import time
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path

from redrive.errors import TransportError

__all__ = [
    "HEADER_BYTES",
    "MAGIC",
    "META_CAPACITY",
    "SHM_DIR",
    "Layout",
    "Segment",
    "process_alive",
    "process_start",
    "remove_stale",
    "segment_path",
    "stale_segments",
]

logger = logging.getLogger(__name__)

SHM_DIR = Path("/dev/shm")
PREFIX = "redrive."
MAGIC = 0x7265647269766531  # "redrive1"
VERSION = 1
PAGE = mmap.PAGESIZE
LINE = 8  # words per cache line
HEADER_BYTES = PAGE  # slot header: one page, so the payload starts page-aligned
META_OFFSET = 256
META_CAPACITY = HEADER_BYTES - META_OFFSET
_MADV_POPULATE_READ = 22  # Linux ≥ 5.14 (not in Python 3.11's mmap module)
_NAME = re.compile(r"^[A-Za-z0-9_.-]{1,200}$")

# control block words
W_MAGIC, W_VERSION, W_SLOTS, W_STRIDE, W_CAPACITY, W_READERS, W_POLICY, W_GENERATION = range(8)
W_OWNER_PID, W_OWNER_START, W_CREATED, W_CLOSED = 8, 9, 10, 11
W_WRITE_SEQ = 16
W_WRITER_WAITING = 26
W_ORDER = 32
READER_WORDS = 16
# reader entry fields (offsets inside an entry)
R_PID, R_START, R_STATE, R_POLICY, R_READ_SEQ, R_PIN, R_DELIVERED, R_DROPPED = range(8)
R_TORN, R_LAG_LAST, R_LAG_MAX, R_LAG_SUM, R_CAPTURE_LAG, R_WAITING = 8, 9, 10, 11, 12, 13
# slot header words
S_BEGIN, S_END, S_STAMP, S_PUBLISH, S_KIND, S_NBYTES, S_META_LEN = 0, 8, 16, 17, 18, 19, 20


def _round_up(n: int, to: int) -> int:
    return (n + to - 1) // to * to


@dataclass(frozen=True, slots=True)
class Layout:
    """Where everything lives in a segment of ``n_slots`` × ``capacity`` bytes."""

    n_slots: int
    capacity: int
    max_readers: int

    @property
    def order_words(self) -> int:
        return _round_up(self.n_slots, LINE)

    def reader_word(self, index: int) -> int:
        """First control word of reader entry ``index``."""
        return W_ORDER + self.order_words + index * READER_WORDS

    @property
    def control_bytes(self) -> int:
        return _round_up(self.reader_word(self.max_readers) * 8, PAGE)

    @property
    def slot_stride(self) -> int:
        return HEADER_BYTES + _round_up(max(self.capacity, 1), PAGE)

    @property
    def total_bytes(self) -> int:
        return self.control_bytes + self.n_slots * self.slot_stride

    def slot_offset(self, slot: int) -> int:
        return self.control_bytes + slot * self.slot_stride


def segment_path(name: str) -> Path:
    """``/dev/shm/redrive.<name>``; ``name`` is letters, digits, ``_ . -`` (see ``stream_name``)."""
    if not _NAME.match(name):
        msg = (
            f"stream name {name!r}: use 1–200 letters, digits, '_', '.' or '-' "
            "(a ROS topic such as /velodyne_points becomes velodyne_points)"
        )
        raise TransportError(msg)
    return SHM_DIR / f"{PREFIX}{name}"


def process_start(pid: int) -> int | None:
    """The start time of process ``pid`` (clock ticks since boot), or None if there is none."""
    try:
        stat = Path(f"/proc/{pid}/stat").read_bytes()
    except OSError:
        return None
    # the command name (field 2) is in parentheses and may hold spaces: split after its end
    fields = stat[stat.rfind(b")") + 2 :].split()
    try:
        return int(fields[19])  # field 22 overall
    except (IndexError, ValueError):
        return None


def process_alive(pid: int, start: int) -> bool:
    """Whether the process ``pid`` that started at ``start`` still runs (and is not a zombie)."""
    if pid <= 0:
        return False
    try:
        stat = Path(f"/proc/{pid}/stat").read_bytes()
    except OSError:
        return False
    tail = stat[stat.rfind(b")") + 2 :].split()
    if not tail or tail[0] in (b"Z", b"X"):
        return False
    try:
        return int(tail[19]) == start
    except (IndexError, ValueError):
        return False


_START_OF: dict[int, int] = {}  # pid → start time, so a forked child reads its own


def self_identity() -> tuple[int, int]:
    """(pid, start time) of this process."""
    pid = os.getpid()
    if pid not in _START_OF:
        _START_OF[pid] = process_start(pid) or 0
    return pid, _START_OF[pid]


class Segment:
    """A mapped segment: the ``mmap``, int64 words over the control block and the slot headers.

    Use :meth:`create` (the writer) or :meth:`attach` (a reader).
    """

    def __init__(self, path: Path, fd: int, mm: mmap.mmap, layout: Layout, *, owner: bool) -> None:
        self.path = path
        self.fd = fd
        self.mm = mm
        self.layout = layout
        self.owner = owner
        self.inode = os.fstat(fd).st_ino
        self.words = memoryview(mm).cast("B").cast("q")
        self._closed = False

    # -- creation ----------------------------------------------------------------------------
    @classmethod
    def create(cls, name: str, layout: Layout, *, policy: int) -> Segment:
        """Create ``/dev/shm/redrive.<name>`` (0600), removing a stale one first.

        Raises:
            TransportError: a live process already writes this stream, or /dev/shm is full.
        """
        path = segment_path(name)
        remove_stale(name)
        try:
            fd = os.open(path, os.O_RDWR | os.O_CREAT | os.O_EXCL | os.O_CLOEXEC, 0o600)
        except FileExistsError as err:
            owner = _owner_of(path)
            msg = (
                f"stream {name!r} already has a live writer (pid {owner}, {path}); "
                "stop it, or pick another stream name"
            )
            raise TransportError(msg) from err
        try:
            os.fchmod(fd, 0o600)
            try:
                os.posix_fallocate(fd, 0, layout.total_bytes)
            except OSError as err:
                msg = (
                    f"cannot reserve {layout.total_bytes / 2**20:.1f} MiB in {SHM_DIR} for stream "
                    f"{name!r}: {err}; free space in /dev/shm or use fewer/smaller slots"
                )
                raise TransportError(msg) from err
            mm = mmap.mmap(
                fd, layout.total_bytes, mmap.MAP_SHARED, mmap.PROT_READ | mmap.PROT_WRITE
            )
        except BaseException:
            os.close(fd)
            path.unlink(missing_ok=True)
            raise
        seg = cls(path, fd, mm, layout, owner=True)
        seg._init_control(policy)
        return seg

    def _init_control(self, policy: int) -> None:
        lay, w = self.layout, self.words
        # pre-touch every page (writing zeros faults them in now, not per message)
        view = memoryview(self.mm)
        for off in range(0, lay.total_bytes, PAGE):
            view[off] = 0
        pid, start = self_identity()
        w[W_SLOTS], w[W_STRIDE], w[W_CAPACITY] = lay.n_slots, lay.slot_stride, lay.capacity
        w[W_READERS], w[W_POLICY] = lay.max_readers, policy
        w[W_GENERATION] = secrets.randbits(62)
        w[W_OWNER_PID], w[W_OWNER_START], w[W_CREATED] = pid, start, time.time_ns()
        for i in range(lay.n_slots):
            w[W_ORDER + i] = -1
        for r in range(lay.max_readers):
            w[lay.reader_word(r) + R_PIN] = -1
        w[W_VERSION] = VERSION
        w[W_MAGIC] = MAGIC  # last: a reader that sees the magic sees an initialised block

    @classmethod
    def attach(cls, name: str) -> Segment:
        """Map an existing segment.

        Raises:
            FileNotFoundError: no such stream (yet).
            TransportError: the file is not a redrive segment of this version.
        """
        path = segment_path(name)
        fd = os.open(path, os.O_RDWR | os.O_CLOEXEC)
        try:
            size = os.fstat(fd).st_size
            if size < PAGE:
                msg = f"{path} is not a redrive stream segment ({size} bytes)"
                raise TransportError(msg)
            mm = mmap.mmap(fd, size, mmap.MAP_SHARED, mmap.PROT_READ | mmap.PROT_WRITE)
        except BaseException:
            os.close(fd)
            raise
        w = memoryview(mm).cast("B").cast("q")
        magic, version = w[W_MAGIC], w[W_VERSION]
        lay = Layout(n_slots=w[W_SLOTS], capacity=w[W_CAPACITY], max_readers=w[W_READERS])
        w.release()
        if magic != MAGIC or version != VERSION or lay.total_bytes != size:
            mm.close()
            os.close(fd)
            if magic == 0:
                raise FileNotFoundError(path)  # still being initialised: try again
            msg = (
                f"{path} is not a redrive v{VERSION} stream segment (magic {magic:#x}, version "
                f"{version}); remove it (rm {path}) if no redrive process uses it"
            )
            raise TransportError(msg)
        return cls(path, fd, mm, lay, owner=False)

    def populate(self) -> None:
        """Map every page of the segment now (a reader, once it has joined): its first touch of
        each slot takes no page fault (the kernel maps 16 pages a fault: 64 for a 4 MiB slot).
        Once, at attach: 11–26 ms for 4 × 16 MiB slots on the 2-vCPU VM at load 11."""
        try:
            self.mm.madvise(_MADV_POPULATE_READ)
        except OSError:  # an older kernel: read a byte of each page
            view = memoryview(self.mm)
            sum(view[::PAGE])
            view.release()

    # -- state -------------------------------------------------------------------------------
    @property
    def generation(self) -> int:
        return int(self.words[W_GENERATION])

    def owner_alive(self) -> bool:
        w = self.words
        return not w[W_CLOSED] and process_alive(int(w[W_OWNER_PID]), int(w[W_OWNER_START]))

    def replaced(self) -> bool:
        """Whether the file at :attr:`path` is no longer this segment (unlinked or re-created)."""
        try:
            return os.stat(self.path).st_ino != self.inode
        except FileNotFoundError:
            return True

    @contextlib.contextmanager
    def locked(self) -> Iterator[None]:
        """An exclusive ``flock`` on the segment file (reader entries are claimed under it)."""
        import fcntl

        fcntl.flock(self.fd, fcntl.LOCK_EX)
        try:
            yield
        finally:
            fcntl.flock(self.fd, fcntl.LOCK_UN)

    def close(self, *, unlink: bool = False) -> None:
        if self._closed:
            return
        self._closed = True
        if unlink:
            self.words[W_CLOSED] = 1
            with contextlib.suppress(FileNotFoundError):
                if os.stat(self.path).st_ino == self.inode:
                    self.path.unlink()
        self.words.release()
        try:
            self.mm.close()
        except BufferError:
            # a zero-copy view still references the map: it is unmapped when the view goes
            logger.debug("segment %s: map kept alive by an outstanding view", self.path)
        os.close(self.fd)


def _owner_of(path: Path) -> str:
    try:
        with path.open("rb") as f:
            data = f.read(8 * (W_OWNER_PID + 1))
        return str(int.from_bytes(data[8 * W_OWNER_PID :], "little", signed=True))
    except OSError:
        return "?"


def _stale(path: Path) -> bool:
    try:
        with path.open("rb") as f:
            head = f.read(8 * (W_OWNER_START + 1))
    except OSError:
        return False
    if len(head) < 8 * (W_OWNER_START + 1):
        # shorter than a control block: a creator died before sizing it (or is sizing it now)
        try:
            return time.time() - path.stat().st_mtime > 5.0
        except OSError:
            return False
    words = [int.from_bytes(head[i : i + 8], "little", signed=True) for i in range(0, len(head), 8)]
    if words[W_MAGIC] != MAGIC:
        try:
            return time.time() - path.stat().st_mtime > 5.0
        except OSError:
            return False
    return not process_alive(words[W_OWNER_PID], words[W_OWNER_START])


def stale_segments() -> list[Path]:
    """redrive segments in /dev/shm whose owner process is gone."""
    return sorted(p for p in SHM_DIR.glob(f"{PREFIX}*") if _stale(p))


def remove_stale(name: str | None = None) -> list[Path]:
    """Unlink the stale segment of stream ``name`` (or every stale redrive segment)."""
    paths = [segment_path(name)] if name is not None else stale_segments()
    removed = []
    for path in paths:
        if path.exists() and _stale(path):
            with contextlib.suppress(FileNotFoundError):
                path.unlink()
                removed.append(path)
                logger.info("removed stale shared-memory segment %s", path)
    return removed
