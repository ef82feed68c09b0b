"""The ROS 2 scraper's receive path: samples taken as Cyclone holds them and copied once into a
caller's buffer (RawReader.taken), and the receiving participant's socket buffer configuration
(receiving_config). In one process on a loopback-only domain; skips without cyclonedds."""

from __future__ import annotations

import os
import socket
import time
from typing import Any

import numpy as np
import pytest

pytest.importorskip("cyclonedds", reason="the ros2 extra (cyclonedds) is not installed")

from redrive.io.ros.typestore import typestore_for
from redrive.live.ros2_dds import (
    DEFAULT,
    RECEIVE_BUFFER_BYTES,
    RawReader,
    RawWriter,
    participant,
    receiving_config,
)

LOOPBACK = (
    '<CycloneDDS><Domain id="any"><General><Interfaces><NetworkInterface address="127.0.0.1"/>'
    "</Interfaces><AllowMulticast>false</AllowMulticast></General></Domain></CycloneDDS>"
)
MSGTYPE = "std_msgs/msg/String"


def test_receiving_config_puts_the_users_configuration_last_so_it_wins() -> None:
    ours = receiving_config(None)
    assert "SocketReceiveBufferSize" in ours
    assert f'max="{RECEIVE_BUFFER_BYTES >> 20}MiB"' in ours
    assert "," not in ours
    assert receiving_config("  ") == ours
    assert receiving_config(LOOPBACK) == f"{ours},{LOOPBACK}"


def _udp_receive_buffers() -> dict[int, int]:
    """SO_RCVBUF of this process's UDP sockets, by file descriptor."""
    out = {}
    for name in os.listdir("/proc/self/fd"):
        fd = int(name)
        try:
            if not os.readlink(f"/proc/self/fd/{fd}").startswith("socket:"):
                continue
            sock = socket.socket(fileno=os.dup(fd))
        except OSError:
            continue
        with sock:
            if sock.type == socket.SOCK_DGRAM:
                out[fd] = sock.getsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF)
    return out


@pytest.fixture
def dp(monkeypatch: pytest.MonkeyPatch) -> Any:
    """A participant on a domain of this test, configured as the scraper configures its own."""
    monkeypatch.setenv("CYCLONEDDS_URI", receiving_config(LOOPBACK))
    return participant(100 + os.getpid() % 100)


def _cdr(store: Any, text: str) -> bytes:
    msg = store.types[MSGTYPE](data=text)
    return bytes(store.serialize_cdr(msg, MSGTYPE))


def _padded(cdr: bytes) -> bytes:
    return cdr.ljust((len(cdr) + 3) & ~3, b"\0")


def test_taken_samples_are_copied_byte_for_byte_into_the_callers_buffer(dp: Any) -> None:
    store = typestore_for(2)[0]
    writer = RawWriter(dp, "/chatter", MSGTYPE, store=store, qos=DEFAULT)
    reader = RawReader(dp, "/chatter", MSGTYPE, store=store, qos=DEFAULT)
    sent = [_cdr(store, text) for text in ("a", "hello", "x" * 200_000)]
    for cdr in sent:
        writer.write(cdr, stamp_ns=1_700_000_000_000_000_000)
    got: list[bytes] = []
    deadline = time.monotonic() + 10.0
    while len(got) < len(sent) and time.monotonic() < deadline:
        with reader.taken() as samples:
            for sample in samples:
                assert sample.source_ns == 1_700_000_000_000_000_000
                slot = np.zeros(sample.nbytes + 8, np.uint8)  # a larger slot, as in the stream
                sample.copy_into(slot)
                got.append(slot[: sample.nbytes].tobytes())
                with pytest.raises(ValueError, match="cannot take a sample"):
                    sample.copy_into(bytearray(sample.nbytes - 1))
        time.sleep(0.01)
    assert got == [_padded(cdr) for cdr in sent]  # as on the wire: RawWriter pads to 4 bytes
    writer.write(sent[1])
    deadline = time.monotonic() + 10.0
    taken: list[tuple[bytes, int]] = []
    while not taken and time.monotonic() < deadline:
        taken = reader.take()
        time.sleep(0.01)
    assert [cdr for cdr, _ in taken] == [_padded(sent[1])]


def test_the_receiving_participant_asks_for_a_larger_socket_receive_buffer(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    with open("/proc/sys/net/core/rmem_max") as f:
        rmem_max = int(f.read())
    if rmem_max < 2 << 20:
        pytest.skip(f"net.core.rmem_max is {rmem_max}: no more than Cyclone's default is granted")
    monkeypatch.setenv("CYCLONEDDS_URI", receiving_config(LOOPBACK))
    before = _udp_receive_buffers()
    dp = participant(1 + (100 + os.getpid()) % 100)  # a domain of its own: new sockets
    new = {fd: size for fd, size in _udp_receive_buffers().items() if fd not in before}
    assert new, "the participant opened no UDP socket"
    # Cyclone's own default asks for 1 MiB, which Linux reports as 2 MiB (twice what it grants)
    assert min(new.values()) > 2 << 20
    del dp
