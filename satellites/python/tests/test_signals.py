"""Ctrl-C reaches a Python satellite blocked in the Rust SDK: a blocking recv and a blocking call both end with
KeyboardInterrupt soon after SIGINT (the GIL is released while waiting, and signals are checked every 40 ms)."""

import signal
import time

import pytest

from conftest import PATIENCE, Output, wait_until

BLOCKED_RECV = """
import time
from flow import Client
c = Client.connect(name="blocked")
sub = c.subscribe("Py.never")
print("waiting", flush=True)
try:
    sub.recv()
except KeyboardInterrupt:
    print("interrupted", time.monotonic(), flush=True)
    raise SystemExit(130)
"""

BLOCKED_CALL = """
import time
from flow import Client
c = Client.connect(name="caller")
print("waiting", flush=True)
try:
    c.call("Py.sleepy", {}, timeout=600)
except KeyboardInterrupt:
    print("interrupted", time.monotonic(), flush=True)
    raise SystemExit(130)
"""


@pytest.mark.parametrize("program", [BLOCKED_RECV, BLOCKED_CALL], ids=["recv", "call"])
def test_sigint_interrupts_a_blocked_wait(agent, client, tmp_path, program):
    client.serve("Py.sleepy", lambda r: time.sleep(600))
    script = tmp_path / "blocked.py"
    script.write_text(program)
    proc = agent.python(script)
    output = Output(proc.stdout)
    try:
        wait_until(lambda: f"'waiting' from the child:\n{output.text()}", lambda: "waiting" in output.snapshot())
        time.sleep(0.3)  # let it block inside recv or call
        sent = time.monotonic()
        proc.send_signal(signal.SIGINT)
        assert proc.wait(timeout=PATIENCE) == 130, output.text()
        line = wait_until(lambda: f"'interrupted' from the child:\n{output.text()}",
                          lambda: next((ln for ln in output.snapshot() if ln.startswith("interrupted ")), None))
        took_ms = (float(line.split()[1]) - sent) * 1000
        print(f"SIGINT -> KeyboardInterrupt in {took_ms:.0f} ms")
    finally:
        proc.kill()
        proc.wait()
