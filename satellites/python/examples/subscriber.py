"""The paper's subscriber: prints the messages of a channel (JSON as JSON, anything else as its size).

    python examples/subscriber.py Demo.counter --count 10
"""

import argparse

from flow import Client


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("channel")
    ap.add_argument("--count", type=int, help="stop after this many messages")
    ap.add_argument("--addr", help="hub address (default $FLOW_ADDR or tcp://127.0.0.1:9000)")
    ap.add_argument("--data-dir", help="the server's data directory, where the token is (default data)")
    args = ap.parse_args()
    with Client.connect(args.addr, data_dir=args.data_dir) as client:
        seen = 0
        try:
            for msg in client.subscribe(args.channel):
                try:
                    print(msg.seq, msg.json(), flush=True)
                except ValueError:
                    print(msg.seq, f"<{len(msg)} bytes>", flush=True)
                seen += 1
                if args.count is not None and seen >= args.count:
                    break
        except KeyboardInterrupt:
            pass


if __name__ == "__main__":
    main()
