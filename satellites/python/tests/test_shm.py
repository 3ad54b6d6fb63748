"""Shared memory from Python: a 1 MB frame published over the hub's Unix socket reaches a Python subscriber there by
reference, and reads as a numpy array that is a view of the segment the process maps (no copy), while a TCP
subscriber of the same channel gets the same bytes by copy."""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np
import pytest

from conftest import PATIENCE, binary, start_hub_process, stop_process, wait_subscribers
from flow import Client

#: The hub's default hub.shm_threshold: payloads of this size and more travel by reference.
THRESHOLD = 4096
#: What the hub's segments are called in /proc/PID/maps.
MEMFD = "memfd:flow-shm"


class Hub:
    """The hub alone (`flow-hub`, no agent modules: nothing here needs them) on free ports and its Unix socket."""

    def __init__(self, data_dir: Path) -> None:
        self.data_dir = data_dir
        env = {k: v for k, v in os.environ.items() if k != "FLOW_SHM"}
        env.update(RUST_LOG=os.environ.get("AGENT_TEST_LOG", "info"), NO_COLOR="1")
        self.proc, self.output = start_hub_process(
            [str(binary("flow-hub")), "--http", "127.0.0.1:0", "--flow-tcp", "127.0.0.1:0", "--flow-unix",
             "flow.sock", "--data-dir", str(data_dir)],
            env,
        )
        lines = self.output.snapshot()
        self.tcp = next(l.split()[2] for l in lines if l.startswith("flow hub: tcp://"))
        self.unix = next(l.split()[2] for l in lines if l.startswith("flow hub: unix:"))

    def client(self, addr: str, name: str) -> Client:
        return Client.connect(addr, data_dir=str(self.data_dir), name=name, queue=16, reconnect=False)

    def stop(self) -> None:
        stop_process(self.proc)


@pytest.fixture
def hub(tmp_path):
    h = Hub(tmp_path / "data")
    yield h
    h.stop()


def mapping_of(address: int) -> str:
    """The line of /proc/self/maps whose range holds `address`: what the kernel says lies there."""
    for line in Path("/proc/self/maps").read_text().splitlines():
        start, end = (int(x, 16) for x in line.split()[0].split("-"))
        if start <= address < end:
            return line
    return ""


def test_a_megabyte_frame_over_the_unix_socket_reads_as_a_numpy_view_of_shared_memory(hub):
    frame = np.random.default_rng(39).integers(0, 256, size=1 << 20, dtype=np.uint8)
    with hub.client(hub.unix, "py-shm-pub") as producer, hub.client(hub.unix, "py-shm-local") as local, \
            hub.client(hub.tcp, "py-tcp-remote") as remote:
        pub = producer.publisher("Py.shm.frames", {"format": "raw"})
        by_reference = local.subscribe("Py.shm.frames")
        by_copy = remote.subscribe("Py.shm.frames")
        wait_subscribers(producer, "Py.shm.frames", 2)

        # The SDK sends a channel's first large message inline while it asks the hub for a segment sized for it (a
        # publisher never waits): frames go by reference once the segment has come.
        for _ in range(100):
            pub.publish(frame)  # from the array's own buffer; the SDK copies it once, into the segment
            msg = by_reference.recv(timeout=PATIENCE)
            copy = by_copy.recv(timeout=PATIENCE)
            assert np.array_equal(np.frombuffer(msg, dtype=np.uint8), frame)
            if msg.in_shared_memory:
                break
        assert msg.in_shared_memory, "100 frames over the Unix socket and none came by reference"
        arr = np.frombuffer(msg, dtype=np.uint8)
        # A view, not a copy: numpy owns nothing, may write nothing, and shares the message's own buffer...
        assert not arr.flags.owndata and not arr.flags.writeable
        assert np.shares_memory(arr, np.asarray(msg.data))
        assert np.array_equal(arr, frame)
        # ...which lies in the hub's memfd segment, mapped into this process, as the kernel tells it.
        first, last = mapping_of(arr.ctypes.data), mapping_of(arr.ctypes.data + arr.nbytes - 1)
        assert MEMFD in first and first == last, (first, last)

        assert not copy.in_shared_memory
        assert np.array_equal(np.frombuffer(copy, dtype=np.uint8), frame)
        assert (copy.seq, copy.ts_us) == (msg.seq, msg.ts_us)

        # The array keeps the message, and so its slot, alive after the message's name is gone.
        del msg
        assert np.array_equal(arr, frame)

        # Below the threshold a payload travels inline, to both.
        pub.publish(b"x" * (THRESHOLD - 1))
        small = by_reference.recv(timeout=PATIENCE)
        assert not small.in_shared_memory and small.bytes() == b"x" * (THRESHOLD - 1)
        assert by_copy.recv(timeout=PATIENCE).bytes() == b"x" * (THRESHOLD - 1)


def test_a_loaned_frame_is_written_in_the_segment_and_arrives_by_reference_without_a_copy(hub):
    frame = np.random.default_rng(51).integers(0, 256, size=1 << 20, dtype=np.uint8)
    with hub.client(hub.unix, "py-loan-pub") as producer, hub.client(hub.unix, "py-loan-sub") as local:
        pub = producer.publisher("Py.shm.loaned", {"format": "raw"})
        sub = local.subscribe("Py.shm.loaned")
        wait_subscribers(producer, "Py.shm.loaned", 1)

        # The first ask for a slot asks the hub for the channel's segment: until it has come there is no loan, and
        # the frame goes the ordinary way.
        loan = None
        for _ in range(100):
            loan = pub.loan(frame.nbytes)
            if loan is not None:
                break
            pub.publish(frame)
            assert np.array_equal(np.frombuffer(sub.recv(timeout=PATIENCE), dtype=np.uint8), frame)
        assert loan is not None, "no slot after 100 frames over the Unix socket"
        assert len(loan) == frame.nbytes and loan.pending

        # Written through numpy straight into the slot, which lies in the hub's memfd segment.
        view = np.frombuffer(loan, dtype=np.uint8)
        assert view.flags.writeable and not view.flags.owndata
        written_at = view.ctypes.data
        assert MEMFD in mapping_of(written_at), mapping_of(written_at)
        view[:] = frame
        # The slot is the subscribers' once published: not while a view of it lives.
        with pytest.raises(BufferError):
            loan.publish()
        del view
        loan.publish()
        assert not loan.pending and len(loan) == 0

        msg = sub.recv(timeout=PATIENCE)
        assert msg.in_shared_memory
        arr = np.frombuffer(msg, dtype=np.uint8)
        assert np.array_equal(arr, frame)
        # The subscriber reads the bytes the producer wrote where they were written: in the hub's segment.
        assert MEMFD in mapping_of(arr.ctypes.data)

        # A shorter message in a larger loan, and a loan given back unpublished.
        loan = pub.loan(frame.nbytes)
        assert loan is not None
        with memoryview(loan) as m:
            m[:5] = b"short"
        loan.publish(length=5)
        assert sub.recv(timeout=PATIENCE).bytes() == b"short"
        spare = pub.loan(frame.nbytes)
        assert spare is not None
        spare.discard()
        with pytest.raises(Exception):
            spare.publish()
        with pytest.raises(ValueError):
            other = pub.loan(16 * 1024)
            assert other is not None
            other.publish(length=32 * 1024)
