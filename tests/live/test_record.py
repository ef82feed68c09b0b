"""``redrive live --record`` without a pipeline, as a drop-in for ``rosbag record``: the same
playback recorded by both, split files, types redrive does not know, refused starts, and the part a
killed session leaves."""

from __future__ import annotations

import hashlib
import os
import signal
import socket
import struct
import subprocess
import sys
import threading
import time
import xmlrpc.client
from collections.abc import Iterator
from pathlib import Path

import pytest

from redrive.io import open_log
from redrive.testing.processes import stop_group
from tests.live.conftest import (
    ROSMASTER,
    RosCore,
    RosProcess,
    _stop_group,
    ros1_missing,
    start_master,
)

HUSKY_BAG = "rosbag1_real/robot_localization_test1_husky.bag"
HUSKY_TOPICS = ["/imu/data", "/husky_velocity_controller/odom", "/fix"]
ros1 = pytest.mark.skipif(ros1_missing() is not None, reason=str(ros1_missing()))

# A publisher of a type no ROS package and no redrive decoder knows, made at run time from its
# definition (as rosbag does for the types of a bag); 20 messages once subscribed, then it exits
# when the test lets it go.  It publishes synchronously (queue_size=None: each message is in the
# socket when publish returns): with a queue, rospy sends from a daemon thread that a loaded
# machine can leave behind, and the messages still queued when the process exits are lost.
CUSTOM_PUBLISHER = r"""
import os, sys, time, warnings
import rospy
from genpy.dynamic import generate_dynamic
DEFINITION = '''string label
float64[] values
Wheel[] wheels
================================================================================
MSG: redrive_test/Wheel
int32 id
float32 speed_mps
'''
Rig = generate_dynamic("redrive_test/Rig", DEFINITION)["redrive_test/Rig"]
Wheel = generate_dynamic("redrive_test/Rig", DEFINITION)["redrive_test/Wheel"]
rospy.init_node("custom_rig", anonymous=True)
warnings.filterwarnings("ignore", "The publisher should be created", SyntaxWarning)
pub = rospy.Publisher(sys.argv[1], Rig, queue_size=None)
print("READY", flush=True)
while pub.get_num_connections() == 0:
    time.sleep(0.05)
for i in range(20):
    pub.publish(Rig(label=f"rig {i}", values=[i, i / 2], wheels=[Wheel(id=i, speed_mps=1.5 * i)]))
    time.sleep(0.01)
print("DONE", flush=True)
while not os.path.exists(sys.argv[2]):  # stays connected until the test lets it go
    time.sleep(0.05)
"""


@pytest.fixture
def master(tmp_path: Path) -> Iterator[RosCore]:
    """A master of this test's own (topics registered by one test never reach another)."""
    reason = ros1_missing()
    if reason is not None:
        pytest.skip(reason)
    core, proc = start_master(tmp_path / "ros")
    try:
        yield core
    finally:
        _stop_group(proc, wait_s=10)


def _redrive(core: RosCore, *args: str) -> subprocess.Popen[str]:
    return subprocess.Popen(
        [sys.executable, "-m", "redrive", "live", "--master", core.uri, *args],
        env=dict(os.environ, ROS_MASTER_URI=core.uri),
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        start_new_session=True,
    )


def _wait_recording(proc: subprocess.Popen[str]) -> str:
    """Read the session's stderr up to its `live: recording` line (it is subscribed then)."""
    assert proc.stderr is not None
    seen = []
    for line in proc.stderr:
        seen.append(line)
        if line.startswith("live: recording"):
            return "".join(seen)
    pytest.fail(f"redrive live ended before recording:\n{''.join(seen)}")


def _subscribed(core: RosCore, node: str, topics: list[str]) -> bool:
    state = xmlrpc.client.ServerProxy(core.uri).getSystemState("/tests")[2]
    subscribers = dict(state[1])
    return all(node in subscribers.get(t, ()) for t in topics)


def _call_set_bool(core: RosCore, service: str, *, value: bool) -> None:
    """Call a std_srvs/SetBool service over TCPROS (stdlib only: Debian ships no std_srvs for
    Python), as `rosservice call SERVICE "data: VALUE"` would."""
    code, status, uri = xmlrpc.client.ServerProxy(core.uri).lookupService("/tests", service)
    assert code == 1, status
    host, port = uri.removeprefix("rosrpc://").rstrip("/").rsplit(":", 1)
    fields = ["callerid=/tests", f"service={service}", "md5sum=*", "persistent=0"]
    blob = b"".join(struct.pack("<I", len(f)) + f.encode() for f in fields)
    with socket.create_connection((host, int(port)), timeout=10) as sock:
        sock.sendall(struct.pack("<I", len(blob)) + blob)
        (size,) = struct.unpack("<I", _recv(sock, 4))
        _recv(sock, size)  # the server's header
        sock.sendall(struct.pack("<IB", 1, int(value)))
        assert _recv(sock, 1) == b"\x01"  # ok


def _recv(sock: socket.socket, size: int) -> bytes:
    out = b""
    while len(out) < size:
        chunk = sock.recv(size - len(out))
        assert chunk, "the service closed the connection"
        out += chunk
    return out


def _connections(core: RosCore, node: str) -> int:
    """How many subscriber connections the node ``node`` has open (its getBusInfo)."""
    master = xmlrpc.client.ServerProxy(core.uri)
    code, _, api = master.lookupNode("/tests", node)
    if code != 1:
        return 0
    _, _, info = xmlrpc.client.ServerProxy(api).getBusInfo("/tests")
    return sum(1 for c in info if c[2] == "o" and c[5])  # outbound, connected


def _per_topic(path: Path, topics: list[str]) -> dict[str, list[str]]:
    out: dict[str, list[str]] = {t: [] for t in topics}
    with open_log(path) as log:
        for m in log.messages(topics=topics):
            out[m.topic].append(hashlib.sha256(bytes(m.raw)).hexdigest())
    return out


def _finish(proc: subprocess.Popen[str], timeout_s: float = 60) -> str:
    try:
        out, err = proc.communicate(timeout=timeout_s)
    finally:
        _stop_group(proc, wait_s=5)
    assert proc.returncode == 0, err
    return out


@ros1
@pytest.mark.shared_data
def test_records_what_rosbag_record_records(
    master: RosCore, tmp_path: Path, shared_data: Path
) -> None:
    """One `rosbag play` of the real Husky bag, recorded by `rosbag record` (C++), by redrive and
    by redrive split into small files: the same messages, byte for byte; both redrive sessions end
    by themselves once the playback is over."""
    (tmp_path / "split").mkdir()
    # paused until all three recorders are connected: none of them misses the first messages;
    # a deep outgoing queue: a recorder slowed down by a loaded machine loses nothing there
    play = subprocess.Popen(
        ["rosbag", "play", "--pause", "--queue", "100000", "-r", "20", "-u", "12",
         str(shared_data / HUSKY_BAG),
         "__name:=player"],
        env=master.env, stdin=subprocess.DEVNULL, stdout=subprocess.DEVNULL,
        stderr=subprocess.PIPE, text=True, start_new_session=True,
    )  # fmt: skip
    whole = _redrive(master, *HUSKY_TOPICS, "--record", str(tmp_path / "husky.mcap"),
                     "--idle-timeout", "1", "--wait", "60")  # fmt: skip
    split = _redrive(master, *HUSKY_TOPICS, "--record", str(tmp_path / "split" / "husky.mcap"),
                     "--split-size", "16K", "--idle-timeout", "1", "--wait", "60")  # fmt: skip
    reference = subprocess.Popen(
        ["rosbag", "record", "-O", str(tmp_path / "reference.bag"), *HUSKY_TOPICS,
         "__name:=reference_recorder"],
        env=master.env, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL,
        start_new_session=True,
    )  # fmt: skip
    try:
        _wait_recording(whole)
        _wait_recording(split)
        deadline = time.monotonic() + 60
        while _connections(master, "/player") < 3 * len(HUSKY_TOPICS):
            assert time.monotonic() < deadline, "the recorders did not connect to rosbag play"
            time.sleep(0.05)
        _call_set_bool(master, "/player/pause_playback", value=False)
        _, err = play.communicate(timeout=120)
        assert play.returncode == 0, err
        summary = _finish(whole)
        _finish(split)
    finally:
        # rosbag record closes its bag on SIGINT. Its Python wrapper leaves at once while the C++
        # recorder still closes the bag (renaming reference.bag.active last): wait for the group
        reference_stopped = stop_group(reference, signal.SIGINT, wait_s=60)
        for proc in (whole, split, play):
            _stop_group(proc, wait_s=5)
    assert reference_stopped, "rosbag record did not close its bag within 60 s of SIGINT"
    want = _per_topic(tmp_path / "reference.bag", HUSKY_TOPICS)
    assert all(len(v) > 10 for v in want.values()), {t: len(v) for t, v in want.items()}
    got = _per_topic(tmp_path / "husky.mcap", HUSKY_TOPICS)
    assert {t: len(v) for t, v in got.items()} == {t: len(v) for t, v in want.items()}
    assert got == want
    assert "stopped: every publisher" in summary
    assert "real time" not in summary
    parts = sorted((tmp_path / "split").iterdir())
    assert len(parts) >= 3
    assert [p.name for p in parts] == [f"husky_{i:04d}.mcap" for i in range(len(parts))]
    total = 0
    for part in parts:  # each file valid on its own
        with open_log(part) as log:
            total += sum(1 for _ in log.messages())
    assert total == sum(len(v) for v in want.values())
    assert _per_topic(tmp_path / "split", HUSKY_TOPICS) == want  # the folder as one log
    assert _per_topic(tmp_path / "split" / "husky_*.mcap", HUSKY_TOPICS) == want  # a glob
    assert not list(tmp_path.rglob(".*.part"))


def _read_until(proc: subprocess.Popen[str], text: str, timeout_s: float = 180.0) -> None:
    """Read ``proc``'s stderr until a line has ``text``; a process that never says it (but
    goes on running) is killed after ``timeout_s`` — generous, for a loaded machine — so the
    test fails with what it said instead of hanging."""
    assert proc.stderr is not None
    seen = []
    watchdog = threading.Timer(timeout_s, proc.kill)
    watchdog.start()
    try:
        for line in proc.stderr:
            seen.append(line)
            if text in line:
                return
    finally:
        watchdog.cancel()
    pytest.fail(f"redrive live never said {text!r} (killed after {timeout_s} s):\n{''.join(seen)}")


def _wait_output(process: RosProcess, text: str) -> None:
    deadline = time.monotonic() + 120  # generous: a loaded machine starts rospy slowly
    while text not in process.output:
        assert process.proc.poll() is None, process.output
        assert time.monotonic() < deadline, process.output
        time.sleep(0.05)


@ros1
def test_a_type_redrive_does_not_know_is_recorded_with_its_definition(tmp_path: Path) -> None:
    """A type made at run time is recorded with its definition; the ROS master killed and started
    again at the same address: a topic published after the restart is recorded too."""
    from mcap.reader import make_reader
    from rosbags.typesys import Stores, get_types_from_msg, get_typestore

    core, master_proc = start_master(tmp_path / "ros")
    free = tmp_path / "let-go"
    live = None
    try:
        with core.python_process(
            CUSTOM_PUBLISHER, "/custom/rig", str(free), timeout_s=120
        ) as first:
            live = _redrive(core, "-e", "/custom/.*", "--record", str(tmp_path / "c.mcap"),
                            "--idle-timeout", "1")  # fmt: skip
            _wait_output(first, "DONE")
            _stop_group(master_proc, wait_s=10)
            _read_until(live, "is gone")
            master_proc = subprocess.Popen(
                [str(ROSMASTER), "--core", "-p", str(core.port)], env=core.env,
                stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, start_new_session=True,
            )  # fmt: skip
            _read_until(live, "is back")
            with core.python_process(
                CUSTOM_PUBLISHER, "/custom/after", str(free), timeout_s=120
            ) as second:
                _wait_output(second, "DONE")
                free.touch()
            _finish(live)
    finally:
        if live is not None:
            _stop_group(live, wait_s=5)
        _stop_group(master_proc, wait_s=10)
    with (tmp_path / "c.mcap").open("rb") as fh:  # the mcap library reads it
        reader = make_reader(fh)
        schema = next(iter(reader.get_summary().schemas.values()))  # type: ignore[union-attr]
        raws: dict[str, list[bytes]] = {}
        for _, channel, message in reader.iter_messages():
            raws.setdefault(channel.topic, []).append(message.data)
    assert schema.name == "redrive_test/Rig"
    assert schema.encoding == "ros1msg"
    assert b"MSG: redrive_test/Wheel" in schema.data
    store = get_typestore(Stores.EMPTY)  # rosbags, from the definition in the file alone
    store.register(get_types_from_msg(schema.data.decode(), "redrive_test/msg/Rig"))
    store.register(get_types_from_msg("int32 id\nfloat32 speed_mps", "redrive_test/msg/Wheel"))
    for topic in ("/custom/rig", "/custom/after"):  # before and after the restart
        rigs = [store.deserialize_ros1(r, "redrive_test/msg/Rig") for r in raws[topic]]
        assert [r.label for r in rigs] == [f"rig {i}" for i in range(20)]
        assert rigs[7].wheels[0].speed_mps == pytest.approx(10.5)
    with open_log(tmp_path / "c.mcap") as log:  # and redrive
        first_rig = log.deserialize(next(log.messages(topics=["/custom/rig"])))
    assert first_rig.values.tolist() == [0.0, 0.0]  # type: ignore[attr-defined]


@ros1
@pytest.mark.parametrize(
    "args", [["/not/there", "--wait", "0"], ["-a", "--master", "http://127.0.0.1:9"]]
)
def test_a_refused_start_leaves_no_file(master: RosCore, tmp_path: Path, args: list[str]) -> None:
    """Nothing is left by a refused start; an unfinished recording of a killed session (its pid
    gone) found there is named with the command that recovers it, and kept."""
    out = tmp_path / "out"
    out.mkdir()
    dead = subprocess.Popen([sys.executable, "-c", "pass"])
    dead.wait()
    orphan = out / f".r.mcap.{dead.pid}-k3j2h1ab.part"
    orphan.write_bytes(b"\x89MCAP0\r\n")
    live = _redrive(master, *args, "--record", str(out / "r.mcap"))
    _, err = live.communicate(timeout=60)
    assert live.returncode != 0
    assert "Traceback" not in err
    assert ("not on the ROS master" in err) or ("no ROS master" in err), err
    assert f"redrive repair {orphan} -o" in " ".join(err.split())
    assert list(out.iterdir()) == [orphan]


def test_parts_of_running_writers_are_not_orphans(tmp_path: Path) -> None:
    from redrive.io.partfiles import create_part, orphaned_parts

    fd, mine = create_part(tmp_path / "a.mcap")
    os.close(fd)
    old = tmp_path / ".b.mcap.xk2j3h4g.part"  # an older version's part: no pid in the name
    old.write_bytes(b"")
    assert orphaned_parts(tmp_path) == [old]
    assert mine.exists()
