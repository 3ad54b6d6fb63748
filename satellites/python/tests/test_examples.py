"""The examples run as users run them: the paper's publisher and subscriber talk through the hub, and ears.py
prints what a transcript channel carries."""

import subprocess

from conftest import EXAMPLES, PATIENCE
from flow import agent as contract


def test_the_paper_publisher_feeds_the_paper_subscriber(agent):
    pub = agent.python(EXAMPLES / "publisher.py", "--channel", "Demo.counter")
    try:
        sub = agent.python(EXAMPLES / "subscriber.py", "Demo.counter", "--count", "3")
        out, _ = sub.communicate(timeout=PATIENCE)
        assert sub.returncode == 0, out.decode()
        rows = out.decode().splitlines()
        assert len(rows) == 3, rows
        ns = [eval(r.split(" ", 1)[1])["n"] for r in rows]  # noqa: S307 - a dict printed by our own example
        assert ns == sorted(ns) and len(set(ns)) == 3
    finally:
        pub.kill()
        out = pub.stdout.read().decode()
        pub.wait()
    assert "Demo.counter: someone listens" in out, out


def test_ears_prints_final_transcripts_and_skips_voice_activity(agent, client):
    transcript = client.publisher(contract.TRANSCRIPT, contract.HEADERS[contract.TRANSCRIPT])
    ears = agent.python(EXAMPLES / "ears.py", "--count", "1", stderr=subprocess.PIPE)
    try:
        # Printed once its subscription is in place (the channel exists, so the hub has attached it).
        assert ears.stderr.readline().decode().startswith("ears: listening"), "ears did not start"
        transcript.publish({"vad": "start", "at_ms": 10, "satellite": "test"})
        transcript.publish({
            "utterance": "u1", "text": "Turn left.", "start_us": 0, "end_us": 900000, "satellite": "whisper-a",
            "model": "tiny.en", "processing_ms": 120, "final": True,
        })
        out, _ = ears.communicate(timeout=PATIENCE)
    finally:
        ears.kill()
        ears.wait()
    assert out.decode().strip() == "Turn left.  (whisper-a, 120 ms)"
