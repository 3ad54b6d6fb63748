"""The PySketch shape of the first SkRobot paper: subclass ``Sketch``, set up channels in ``setup()``, react in the
tick handlers and ``on_message``; ``run()`` blocks until Ctrl-C.

    class Counter(Sketch):
        def setup(self):
            self.out = self.client.publisher("Demo.count")
            self.subscribe(agent.TRANSCRIPT)
            self.n = 0

        def one_sec_tick(self):
            self.n += 1
            self.out.publish({"n": self.n})

        def on_message(self, channel, msg):
            print(channel, msg.json())

    Counter(addr="tcp://127.0.0.1:9000").run()

Only the pulses whose handler a subclass overrides are scheduled, so an idle sketch sleeps.
"""

from __future__ import annotations

from typing import Any, Optional

from ._native import Client, ConnectionLost, Events, Message, Subscription


class Sketch:
    """A satellite written as ``setup`` plus handlers, driven by FastTick, SlowTick and OneSecTick."""

    #: FastTick period in milliseconds (the paper's 10 ms).
    fast_ms: float = 10.0
    #: SlowTick period in milliseconds (the paper's 100 ms).
    slow_ms: float = 100.0

    def __init__(
        self,
        addr: Optional[str] = None,
        token: Optional[str] = None,
        data_dir: Optional[str] = None,
        name: Optional[str] = None,
        **connect: Any,
    ) -> None:
        self._connect = dict(addr=addr, token=token, data_dir=data_dir, name=name or type(self).__name__, **connect)
        self.client: Client = None  # type: ignore[assignment]  # set by run() before setup()
        self._subscriptions: list[Subscription] = []
        self._events: Optional[Events] = None
        self._stopping = False

    # ------------------------------------------------------------------ what subclasses override

    def setup(self) -> None:
        """Runs once after login: create publishers and services, ``subscribe`` to channels."""

    def fast_tick(self) -> None:
        """Every ``fast_ms`` (scheduled only when overridden)."""

    def slow_tick(self) -> None:
        """Every ``slow_ms`` (scheduled only when overridden)."""

    def one_sec_tick(self) -> None:
        """Every second (scheduled only when overridden)."""

    def on_message(self, channel: str, msg: Message) -> None:
        """A message on a channel this sketch subscribed to with ``subscribe``."""

    def teardown(self) -> None:
        """Runs once when the sketch stops, before the connection closes."""

    # ------------------------------------------------------------------ what subclasses call

    def subscribe(self, channel: str) -> Subscription:
        """Subscribes in ``setup``; the messages arrive in ``on_message``."""
        if self._events is not None:
            raise RuntimeError("Sketch.subscribe belongs in setup(): the event loop is already running")
        sub = self.client.subscribe(channel)
        self._subscriptions.append(sub)
        return sub

    def stop(self) -> None:
        """Makes ``run`` return after the current handler."""
        self._stopping = True

    def jitter(self) -> dict:
        """Lateness of each pulse against its schedule so far (see ``Events.jitter``)."""
        return self._events.jitter() if self._events is not None else {}

    # ------------------------------------------------------------------ the loop

    def _overridden(self, method: str) -> bool:
        return getattr(type(self), method) is not getattr(Sketch, method)

    def run(self) -> None:
        """Connects, runs ``setup``, then handles pulses and messages until Ctrl-C, ``stop()`` or a closed client."""
        self.client = Client.connect(**{k: v for k, v in self._connect.items() if v is not None})
        try:
            self.setup()
            self._events = Events(
                self._subscriptions,
                fast_ms=self.fast_ms if self._overridden("fast_tick") else None,
                slow_ms=self.slow_ms if self._overridden("slow_tick") else None,
                one_sec=self._overridden("one_sec_tick"),
            )
            handlers = {"fast": self.fast_tick, "slow": self.slow_tick, "one_sec": self.one_sec_tick}
            while not self._stopping:
                kind, msg = self._events.next()
                if msg is not None:
                    self.on_message(msg.channel, msg)
                else:
                    handlers[kind]()
        except KeyboardInterrupt:
            pass
        except ConnectionLost:
            if not self._stopping:
                raise
        finally:
            try:
                self.teardown()
            finally:
                self.client.close()
