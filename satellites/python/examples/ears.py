"""Prints what the agent hears: every final transcript on the agent's transcript channel, with who heard it and how
long it took, and voice-activity events with --vad.

    python examples/ears.py
"""

import argparse
import sys

from flow import Client, agent


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--vad", action="store_true", help="also print voice-activity events")
    ap.add_argument("--count", type=int, help="stop after this many transcripts")
    ap.add_argument("--addr", help="hub address (default $FLOW_ADDR or tcp://127.0.0.1:9000)")
    ap.add_argument("--data-dir", help="the server's data directory, where the token is (default data)")
    args = ap.parse_args()
    heard = 0
    with Client.connect(args.addr, data_dir=args.data_dir) as client:
        transcripts = client.subscribe(agent.TRANSCRIPT)
        print(f"ears: listening on {agent.TRANSCRIPT}", file=sys.stderr, flush=True)
        try:
            for msg in transcripts:
                h = agent.Heard.from_msg(msg)
                if h.vad is not None:
                    if args.vad:
                        print(f"[vad {h.vad}]", flush=True)
                    continue
                if not h.text or h.partial:
                    continue
                fields = msg.json()
                who = fields.get("satellite", "?")
                took = fields.get("processing_ms")
                suffix = f"  ({who}, {took} ms)" if took is not None else ""
                print(f"{h.text}{suffix}", flush=True)
                heard += 1
                if args.count is not None and heard >= args.count:
                    break
        except KeyboardInterrupt:
            pass


if __name__ == "__main__":
    main()
