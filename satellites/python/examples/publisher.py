"""The paper's publisher: a counter as JSON on a streaming channel, published only while someone listens.

    python examples/publisher.py --channel Demo.counter
"""

import argparse
import time

from flow import Sketch


class Publisher(Sketch):
    """Every SlowTick (100 ms), the next number, if anyone subscribes."""

    def __init__(self, channel: str, **connect):
        super().__init__(**connect)
        self.channel = channel
        self.n = 0

    def setup(self):
        self.out = self.client.publisher(
            self.channel,
            {"format": "json", "content": "counter"},
            on_subscribers=lambda on: print(f"{self.channel}: {'someone listens' if on else 'nobody listens'}"),
        )

    def slow_tick(self):
        if self.out.has_subscribers:
            self.n += 1
            self.out.publish({"n": self.n, "t": time.time()})


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--channel", default="Demo.counter")
    ap.add_argument("--addr", help="hub address (default $FLOW_ADDR or tcp://127.0.0.1:9000)")
    ap.add_argument("--data-dir", help="the server's data directory, where the token is (default data)")
    args = ap.parse_args()
    Publisher(args.channel, addr=args.addr, data_dir=args.data_dir).run()


if __name__ == "__main__":
    main()
