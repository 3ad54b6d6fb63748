"""The Sketch shape: setup once, the three pulses in proportion, messages in on_message, stop() and teardown."""

import threading

from conftest import PATIENCE, wait_subscribers, wait_until
from flow import Client, Sketch


class Counting(Sketch):
    def setup(self):
        self.counts = {"fast": 0, "slow": 0, "one_sec": 0}
        self.heard = []
        self.torn_down = False
        self.subscribe("Py.sketch.in")
        self.out = self.client.publisher("Py.sketch.out")

    def fast_tick(self):
        self.counts["fast"] += 1

    def slow_tick(self):
        self.counts["slow"] += 1

    def one_sec_tick(self):
        self.counts["one_sec"] += 1
        if self.counts["one_sec"] == 2:
            self.stop()

    def on_message(self, channel, msg):
        self.heard.append((channel, msg.json()))
        self.out.publish({"echo": msg.json()})

    def teardown(self):
        self.torn_down = True


def test_pulses_fire_in_proportion_and_messages_reach_on_message(agent):
    sketch = Counting(addr=agent.addr, data_dir=str(agent.data_dir))
    runner = threading.Thread(target=sketch.run)
    runner.start()
    with Client.connect(agent.addr, data_dir=str(agent.data_dir)) as peer:
        echoes = peer.subscribe("Py.sketch.out")
        pub = peer.publisher("Py.sketch.in")
        assert pub.wait_subscribers(timeout=PATIENCE)
        # The sketch subscribes before it creates its publisher, and our subscription to that publisher's channel
        # takes effect only once the channel exists: an echo sent before that would be lost (seen on a loaded CI
        # machine).
        wait_subscribers(peer, "Py.sketch.out", 1)
        pub.publish({"hello": "sketch"})
        assert echoes.recv(timeout=PATIENCE).json() == {"echo": {"hello": "sketch"}}
    runner.join(timeout=PATIENCE)
    assert not runner.is_alive(), "stop() did not end run()"
    c = sketch.counts
    assert c["one_sec"] == 2
    # Two seconds of 10 ms and 100 ms pulses: counted loosely, a loaded machine skips late ticks.
    assert 5 <= c["slow"] <= 21, c
    assert 40 <= c["fast"] <= 201, c
    assert c["fast"] > c["slow"] > c["one_sec"]
    assert sketch.heard == [("Py.sketch.in", {"hello": "sketch"})]
    assert sketch.torn_down
    jitter = sketch.jitter()
    assert jitter["fast"]["ticks"] == c["fast"]


class Idle(Sketch):
    """Overrides no pulse: nothing is scheduled, so it only wakes for its message."""

    def setup(self):
        self.subscribe("Py.idle")

    def on_message(self, channel, msg):
        self.got = msg.text()
        self.stop()


def test_a_sketch_without_tick_handlers_schedules_no_pulses(agent):
    sketch = Idle(addr=agent.addr, data_dir=str(agent.data_dir))
    runner = threading.Thread(target=sketch.run)
    runner.start()
    with Client.connect(agent.addr, data_dir=str(agent.data_dir)) as peer:
        pub = peer.publisher("Py.idle")
        assert pub.wait_subscribers(timeout=PATIENCE)
        pub.publish("wake up")
        runner.join(timeout=PATIENCE)
    assert sketch.got == "wake up"
    assert all(j["ticks"] == 0 for j in sketch.jitter().values())
