"""A full memory fence callable from Python, and the memory-ordering argument of the channel.

The channel (:mod:`redrive.transport.channel`) is a single-writer seqlock ring in shared memory,
read by up to ``max_readers`` processes, with no lock. Everything it needs from the hardware:

**Plain 8-byte stores and loads are single-copy atomic.** Every shared word (sequence numbers,
pins, counters) is an aligned int64 accessed through a ``memoryview`` cast to ``"q"``; CPython
reads and writes such an item with one ``memcpy`` of 8 bytes, which compilers emit as one 64-bit
``mov`` (x86-64) or ``ldr``/``str`` (AArch64) — aligned 64-bit accesses are atomic on both (Intel
SDM vol. 3 §9.1.1; Arm ARM B2.2.1). No word is ever torn; only the *order* in which other cores
see them needs an argument.

**No compiler reordering.** Each Python statement runs to completion in the interpreter before
the next starts, and every store goes through an opaque C call (``memcpy``, numpy ``copyto``), so
the C compiler cannot move a store across another; the program order of the statements below is
the order the CPU receives.

**Writer** (one process): ① ``seq_begin[s] = n`` (the slot is being written: ``seq_begin !=
seq_end``), ② FENCE, ③ read the readers' pins — if one pins ``s``, put ``seq_begin`` back and
take another slot, ④ payload and header, ⑤ FENCE (AArch64 only), ⑥ ``seq_end[s] = n``,
⑦ ``order[n % N] = s``, ⑧ ``write_seq = n``, then the wake-ups below.

**Reader**: ⓐ load ``write_seq``, ⓑ FENCE (AArch64 only: loads after it are not satisfied before
it), ⓒ ``s = order[m % N]``, ⓓ ``pin = s``, ⓔ FENCE, ⓕ load ``seq_begin[s]``, ``seq_end[s]``:
both must equal ``m``, else unpin and retry (the slot was reused), ⓖ copy or view the payload,
ⓗ FENCE (AArch64 only), ⓘ re-load ``seq_begin[s]`` and ``seq_end[s]``: still ``m`` (a torn-read
guard that the pin makes unreachable), ⓙ ``pin = -1``, ``read_seq = m``.

*x86-64 (TSO)*: stores become visible to other cores in program order, and loads are not
reordered with older loads, so ①④⑥⑦⑧ are seen in that order and a reader that sees ``write_seq
= n`` (ⓐ) sees the finished slot (ⓒⓕⓖ). The one reordering TSO allows — a load passing an older
store to another address, through the store buffer — would break the pin handshake, a Dekker
pattern: writer *store seq_begin, load pins*, reader *store pin, load seq_begin*. Without ② and
ⓔ both loads could miss the other side's store, the writer would reuse a slot the reader is
reading. With a full fence (``mfence``) on each side at least one sees the other: either the
writer sees the pin and leaves the slot, or the reader sees ``seq_begin != m`` and lets go. The
AArch64-only fences are compiled out here (no instruction is needed for them).

*AArch64 (weakly ordered)*: stores to different addresses may become visible in any order and
loads may be satisfied in any order, so the fences marked "AArch64 only" are needed too: ⑤ makes
the payload visible before ``seq_end``/``write_seq`` (release), ⓑ keeps the slot loads after
``write_seq`` (acquire), ⓗ keeps the re-check after the payload reads (the seqlock's read-side
barrier, as in the Linux kernel's ``read_seqcount_retry``). ``dmb ish`` (what the fence below
emits there) orders all of them.

**Wake-ups** follow the same pattern twice. A reader about to sleep stores its ``waiting`` flag,
fences, and re-loads ``write_seq`` before blocking on its ``eventfd``; the writer, after ⑧,
fences and signals only the readers whose flag it sees. One of the two loads sees the other
side's store, so a reader never sleeps through a message while the writer skips the system call
for readers that are busy. Lossless back-pressure mirrors it: the writer stores
``writer_waiting``, fences and re-checks the readers' ``read_seq``; a lossless reader stores
``read_seq``, fences and signals the writer only if it sees the flag.

The fence is C11 ``atomic_thread_fence(memory_order_seq_cst)``, exported as a function by GCC's
``libatomic`` (``mfence``/``lock or`` on x86-64, ``dmb ish`` on AArch64), called through ctypes
without releasing the GIL (≈ 0.15 µs; on x86-64, where the library's code is read to be a fence
whatever the order, without the argument — see :func:`ignores_its_order`). The fences that only
weakly ordered CPUs need are written ``if WEAK_ORDERING: fence()`` on the per-message paths, so
x86-64 pays no call for them.
"""

from __future__ import annotations

import ctypes
import ctypes.util
import functools
import platform
from collections.abc import Callable
from typing import Any

from redrive.errors import TransportError

__all__ = ["WEAK_ORDERING", "fence", "ignores_its_order", "ordered"]

_SEQ_CST = 5  # memory_order_seq_cst

#: True where stores and loads may be reordered with each other beyond TSO (everything but x86).
WEAK_ORDERING = platform.machine().lower() not in ("x86_64", "amd64", "i386", "i686")


def _load_fence() -> Callable[[], None]:
    name = ctypes.util.find_library("atomic") or "libatomic.so.1"
    try:
        # PyDLL: the call keeps the GIL (a fence has no reason to release it, and releasing and
        # re-taking it is a third of a CDLL call's cost: ≈ 1,660 → 1,250 instructions)
        lib = ctypes.PyDLL(name)
        func = lib.atomic_thread_fence
    except (OSError, AttributeError) as err:
        msg = (
            f"redrive.transport needs GCC's libatomic for a memory fence ({err}); "
            "install it (Debian: apt-get install libatomic1)"
        )
        raise TransportError(msg) from err
    # no argtypes: ctypes passes a Python int as a C int by default, and skipping the argument
    # conversion and a Python wrapper halves the call (≈ 0.4 → 0.2 µs, two per message and side)
    func.restype = None
    if ignores_its_order(func):
        # called without the order: no argument to convert (≈ 1,240 → 680 instructions a call)
        return func
    return functools.partial(func, _SEQ_CST)


#: x86-64 code of a sequentially consistent fence as compilers emit it (``mfence``,
#: ``lock orq $0, (%rsp)``, ``lock orl $0, (%rsp)``), each followed by ``ret``
_X86_64_FENCES = tuple(bytes.fromhex(h) + b"\xc3" for h in ("0faef0", "f048830c2400", "f0830c2400"))
_ENDBR64 = bytes.fromhex("f30f1efa")


def ignores_its_order(func: Any) -> bool:
    """Whether the C function ``func`` (libatomic's ``atomic_thread_fence(int order)``) is, on
    x86-64, a full fence and a return whatever its argument — then calling it without one is
    the same fence. GCC builds it so (a memory order that is not a compile-time constant is
    taken as ``seq_cst``: the body is ``lock orq $0, (%rsp); ret``), but that is read from the
    code here, not assumed: anything else (another CPU, a library that looks at the order) is
    called with ``memory_order_seq_cst``."""
    if platform.machine().lower() not in ("x86_64", "amd64"):
        return False
    address = ctypes.cast(func, ctypes.c_void_p).value
    if not address:
        return False
    # byte by byte, each read only while the bytes before match a pattern: nothing past the
    # function's own instructions is read (a short function at the end of its mapping)
    return any(
        _starts_with(address, pattern) or _starts_with(address, _ENDBR64 + pattern)
        for pattern in _X86_64_FENCES
    )


def _starts_with(address: int, pattern: bytes) -> bool:
    return all(ctypes.string_at(address + i, 1)[0] == byte for i, byte in enumerate(pattern))


#: a full (sequentially consistent) memory fence.
fence: Callable[[], None] = _load_fence()


def _nothing() -> None:
    return None


#: the fences only weakly ordered CPUs need (a no-op on x86-64).
ordered: Callable[[], None] = fence if WEAK_ORDERING else _nothing
