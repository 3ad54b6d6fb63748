"""Publish and subscribe between Python and Rust satellites (flowctl), both ways, for JSON, PCM and JPEG, with
sync and async iteration and the drop-oldest policy of a slow reader."""

import asyncio
import json
import wave

import numpy as np
import pytest

from conftest import PATIENCE, fixtures, recv_until, wait_until
from flow import Client
from flow import TimeoutError as FlowTimeout


def jpeg_bytes() -> bytes:
    return (fixtures() / "faces" / "derived" / "fr_two_people_640x360.jpg").read_bytes()


def pcm_of_fixture() -> np.ndarray:
    with wave.open(str(fixtures() / "audio" / "LJ001-0002.wav")) as w:
        assert (w.getnchannels(), w.getsampwidth(), w.getframerate()) == (1, 2, 22050)
        return np.frombuffer(w.readframes(w.getnframes()), dtype="<i2")


def test_json_published_in_python_reaches_a_rust_subscriber(agent, client):
    pub = client.publisher("Py.json", {"format": "json"})
    echo = agent.flowctl("echo", "Py.json", "--count", "3", "--json")
    assert pub.wait_subscribers(timeout=PATIENCE), "flowctl never subscribed"
    for i in range(3):
        pub.publish({"i": i, "word": "ciao"})
    out, err = echo.communicate(timeout=PATIENCE)
    assert echo.returncode == 0, err.decode()
    rows = [json.loads(line) for line in out.decode().splitlines()]
    assert [r["json"] for r in rows] == [{"i": i, "word": "ciao"} for i in range(3)]
    assert [r["seq"] for r in rows] == [1, 2, 3]


def test_json_published_by_rust_arrives_in_python_in_order(agent, client):
    sub = client.subscribe("Rust.json")
    lines = b"".join(json.dumps({"n": n}).encode() + b"\n" for n in range(5))
    agent.flowctl_run("pub", "Rust.json", "--wait-subscriber", input=lines)
    got = [sub.recv(timeout=PATIENCE) for _ in range(5)]
    assert [m.json() for m in got] == [{"n": n} for n in range(5)]
    assert [m.seq for m in got] == [1, 2, 3, 4, 5]
    assert all(m.channel == "Rust.json" and m.ts_us > 0 and m.gap == 0 for m in got)


def test_a_jpeg_from_rust_arrives_byte_for_byte_as_a_zero_copy_view(agent, client):
    picture = jpeg_bytes()
    sub = client.subscribe("Rust.jpeg")
    path = fixtures() / "faces" / "derived" / "fr_two_people_640x360.jpg"
    agent.flowctl_run("pub", "Rust.jpeg", "--file", str(path), "--wait-subscriber")
    msg = sub.recv(timeout=PATIENCE)
    view = msg.data
    assert isinstance(view, memoryview) and view.readonly
    assert view == picture and msg.bytes() == picture and len(msg) == len(picture)
    # The view keeps the message alive after the name is gone.
    del msg
    assert view.tobytes()[:2] == b"\xff\xd8"


def test_a_jpeg_from_python_arrives_byte_for_byte_in_rust(agent, client, tmp_path):
    picture = jpeg_bytes()
    pub = client.publisher("Py.jpeg", {"format": "jpeg", "width": 640, "height": 360})
    saved = tmp_path / "saved"
    echo = agent.flowctl("echo", "Py.jpeg", "--count", "2", "--save", str(saved))
    assert pub.wait_subscribers(timeout=PATIENCE)
    pub.publish(picture)
    pub.publish(bytearray(picture))
    _, err = echo.communicate(timeout=PATIENCE)
    assert echo.returncode == 0, err.decode()
    assert (saved / "1.bin").read_bytes() == picture
    assert (saved / "2.bin").read_bytes() == picture


def test_pcm_streamed_by_rust_reads_as_int16_arrays_equal_to_the_recording(agent, client):
    samples = pcm_of_fixture()
    sub = client.subscribe("Rust.pcm")
    wav = fixtures() / "audio" / "LJ001-0002.wav"
    agent.flowctl_run("pub-wav", "Rust.pcm", str(wav), "--chunk-ms", "20", "--wait-subscriber")
    chunks = []

    def complete(chunk) -> bool:
        assert chunk.dtype == np.int16
        chunks.append(chunk)
        return sum(map(len, chunks)) >= len(samples)

    recv_until(sub, f"all {len(samples)} samples", complete, decode=lambda m: m.pcm())
    assert len(chunks[0]) == 441  # 20 ms at 22050 Hz
    assert np.array_equal(np.concatenate(chunks), samples)


def test_pcm_published_from_numpy_arrives_as_the_same_samples_in_rust(agent, client, tmp_path):
    samples = pcm_of_fixture()[: 441 * 4]
    pub = client.publisher("Py.pcm", {"format": "s16le", "rate": 22050, "channels": 1, "chunk_ms": 20})
    saved = tmp_path / "pcm"
    echo = agent.flowctl("echo", "Py.pcm", "--count", "4", "--save", str(saved))
    assert pub.wait_subscribers(timeout=PATIENCE)
    for i in range(4):
        pub.publish(samples[i * 441 : (i + 1) * 441])  # an int16 array view, sent from its buffer
    _, err = echo.communicate(timeout=PATIENCE)
    assert echo.returncode == 0, err.decode()
    got = b"".join((saved / f"{i}.bin").read_bytes() for i in range(1, 5))
    assert got == samples.tobytes()


def test_an_async_for_loop_receives_what_a_python_publisher_sends(client):
    pub = client.publisher("Py.async")
    sub = client.subscribe("Py.async")
    assert pub.wait_subscribers(timeout=PATIENCE)

    async def consume():
        seen = []
        async for msg in sub:
            seen.append(msg.json()["k"])
            if len(seen) == 3:
                return seen

    async def main():
        task = asyncio.create_task(consume())
        for k in range(3):
            pub.publish({"k": k})
        return await asyncio.wait_for(task, PATIENCE)

    assert asyncio.run(main()) == [0, 1, 2]


def test_a_slow_reader_loses_the_oldest_messages_and_counts_them(agent):
    with Client.connect(agent.addr, data_dir=str(agent.data_dir), queue=4) as slow, \
            Client.connect(agent.addr, data_dir=str(agent.data_dir)) as fast:
        sub = slow.subscribe("Py.flood")
        pub = fast.publisher("Py.flood")
        assert pub.wait_subscribers(timeout=PATIENCE)
        for n in range(1, 501):
            pub.publish({"n": n})
        # Drain until the newest arrives: everything that is left must end with it.
        seen = []

        def newest(msg) -> bool:
            seen.append(msg)
            return msg.json()["n"] == 500

        recv_until(sub, "the newest message (n = 500)", newest)
        assert len(seen) < 500
        lost = sum(m.gap for m in seen) + (seen[0].seq - 1)
        assert lost == 500 - len(seen), "every missing message shows as a gap"
        assert lost > 0


def test_recv_with_a_timeout_raises_the_flow_timeout(client):
    sub = client.subscribe("Py.silent")
    with pytest.raises(FlowTimeout, match="Py.silent"):
        sub.recv(timeout=0.2)
    assert sub.try_recv() is None


def test_publishing_something_without_bytes_is_a_clear_type_error(client):
    pub = client.publisher("Py.typed")
    with pytest.raises(TypeError, match="cannot publish a int"):
        pub.publish(42)


def test_first_and_last_subscriber_callbacks_fire(agent, client):
    news = []
    pub = client.publisher("Py.news", on_subscribers=news.append)
    echo = agent.flowctl("echo", "Py.news")
    wait_until("the first-subscriber news", lambda: news == [True])
    echo.kill()
    echo.wait()
    wait_until("the last-subscriber news", lambda: news == [True, False])
    assert not pub.has_subscribers


def test_a_subscriber_waiting_before_the_channel_exists_counts_as_the_first(agent, client):
    early = client.subscribe("Py.early")
    news = []
    assert not any(c["name"] == "Py.early" for c in client.channels()), "the channel does not exist yet"
    with Client.connect(agent.addr, data_dir=str(agent.data_dir)) as owner:
        pub = owner.publisher("Py.early", on_subscribers=news.append)
        wait_until("the news of the subscriber that was already waiting", lambda: news == [True])
        pub.publish("first")
        assert early.recv(timeout=PATIENCE).text() == "first"
