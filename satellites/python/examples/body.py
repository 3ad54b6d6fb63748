"""A robot body: serves Robot.command, which the agent's default rule program calls for "turn left" and "turn
right", turns (here: keeps a heading in the pair database) and answers with the sentence the agent says.

    python examples/body.py
"""

import argparse

from flow import Sketch

COMMANDS = "Robot.command"
STEP_DEG = 90


class Body(Sketch):
    """The body's state is its heading; the pair database keeps it across restarts."""

    def setup(self):
        self.heading = int(self.client.db.get("robot.heading", 0))
        self.service = self.client.serve(
            COMMANDS,
            self.command,
            {"takes": {"action": "turn", "direction": "left|right"}, "answers": {"text": "what to say"}},
        )
        print(f"body: serving {COMMANDS}, heading {self.heading} degrees", flush=True)

    def command(self, request):
        cmd = request.json()
        if cmd.get("action") != "turn" or cmd.get("direction") not in ("left", "right"):
            raise ValueError(f"cannot do {cmd}")
        sign = -1 if cmd["direction"] == "left" else 1
        self.heading = (self.heading + sign * STEP_DEG) % 360
        self.client.db.set("robot.heading", self.heading)
        print(f"body: turned {cmd['direction']}, heading {self.heading} degrees", flush=True)
        return {"text": f"Turning {cmd['direction']}. I now face {self.heading} degrees."}


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--addr", help="hub address (default $FLOW_ADDR or tcp://127.0.0.1:9000)")
    ap.add_argument("--data-dir", help="the server's data directory, where the token is (default data)")
    args = ap.parse_args()
    Body(addr=args.addr, data_dir=args.data_dir, name="robot-body").run()


if __name__ == "__main__":
    main()
