"""The suite's own waiting helper ends: `recv_until` fails by its one deadline on a channel that keeps delivering
messages that never match (as Agent.avatar's blinks kept a loop of per-message timeouts going for ever), and on a
silent one, naming what it waited for."""

import re
import threading
import time

import pytest

from conftest import PATIENCE, recv_until


def test_a_busy_stream_that_never_matches_ends_at_the_deadline_naming_what_was_awaited(client):
    pub = client.publisher("Py.busy")
    sub = client.subscribe("Py.busy")
    assert pub.wait_subscribers(timeout=PATIENCE)
    stop = threading.Event()

    def chatter() -> None:
        n = 0
        while not stop.is_set():
            n += 1
            pub.publish({"blink": n})
            stop.wait(0.05)

    publisher = threading.Thread(target=chatter, daemon=True)
    publisher.start()
    try:
        sub.recv(timeout=PATIENCE)  # the stream is busy before the wait starts
        started = time.monotonic()
        with pytest.raises(pytest.fail.Exception) as failed:
            recv_until(sub, "a message that never comes", lambda m: False, timeout=1.5, decode=lambda m: m.json())
        assert time.monotonic() - started >= 1.5, "it gave up before its deadline"
    finally:
        stop.set()
        publisher.join()
    text = str(failed.value)
    found = re.search(r"waiting for a message that never comes on Py\.busy: (\d+) messages, none matched; "
                      r"the last: \{'blink': \d+\}$", text)
    assert found, text
    assert int(found[1]) >= 2, f"the stream kept delivering while it waited: {text}"


def test_a_silent_stream_ends_at_the_deadline_having_seen_nothing(client):
    sub = client.subscribe("Py.quiet")
    with pytest.raises(pytest.fail.Exception, match="a word on Py.quiet: 0 messages, none matched$"):
        recv_until(sub, "a word", lambda m: True, timeout=0.3)
