"""Serial lines from Python and flowctl: the hub serves one end of a pair of linked pseudo-terminals (Debian's
socat), and a satellite on the other end, the Python SDK or flowctl, reaches the TCP satellites as over any other
transport (docs/protocol.md, "Serial lines")."""

import json
import subprocess
import time
from pathlib import Path

import pytest

from conftest import LEAN, PATIENCE, Agent, binary, wait_until
from flow import Client


@pytest.fixture
def line(tmp_path):
    """Two linked pseudo-terminals: (the hub's end, the satellite's end)."""
    hub_end, board_end = tmp_path / "hub-line", tmp_path / "board-line"
    socat = subprocess.Popen(
        ["socat", f"pty,raw,echo=0,link={hub_end}", f"pty,raw,echo=0,link={board_end}"],
        stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL,
    )
    wait_until("socat to make its terminals", lambda: hub_end.exists() and board_end.exists())
    yield hub_end, board_end
    socat.kill()
    socat.wait()


@pytest.fixture
def hub_on_line(tmp_path, line):
    config = LEAN + f'\n[[hub.serial]]\npath = "{line[0]}"\nbaud = 115200\n'
    a = Agent(tmp_path / "data", config=config).start()
    yield a
    a.stop()


def test_a_python_satellite_on_a_serial_line_reaches_a_rust_subscriber(hub_on_line, line):
    agent = hub_on_line
    board = Client.connect(f"serial:{line[1]}?baud=115200", data_dir=str(agent.data_dir), name="py-board")
    try:
        pub = board.publisher("Py.serial", {"format": "json"})
        echo = agent.flowctl("echo", "Py.serial", "--count", "3", "--json")
        assert pub.wait_subscribers(timeout=PATIENCE), "flowctl never subscribed"
        for i in range(3):
            pub.publish({"i": i, "over": "serial"})
        out, err = echo.communicate(timeout=PATIENCE)
        assert echo.returncode == 0, err.decode()
        rows = [json.loads(row) for row in out.decode().splitlines()]
        assert [r["json"] for r in rows] == [{"i": i, "over": "serial"} for i in range(3)]
    finally:
        board.close()


def test_flowctl_on_a_serial_line_publishes_to_a_python_subscriber(hub_on_line, line):
    agent = hub_on_line
    client = Client.connect(agent.addr, data_dir=str(agent.data_dir), name="py-watcher")
    try:
        sub = client.subscribe("Rust.serial")
        lines = b"".join(json.dumps({"n": n}).encode() + b"\n" for n in range(5))
        proc = subprocess.run(
            [str(binary("flowctl")), "--addr", f"serial:{line[1]}", "--data-dir", str(agent.data_dir),
             "pub", "Rust.serial", "--wait-subscriber"],
            input=lines, capture_output=True, timeout=PATIENCE,
        )
        assert proc.returncode == 0, proc.stderr.decode()
        got = [sub.recv(timeout=PATIENCE) for _ in range(5)]
        assert [m.json() for m in got] == [{"n": n} for n in range(5)]
    finally:
        client.close()
