"""UDP from Python and flowctl: a hub serving FlowProtocol over UDP (`server.flow_udp`), a Python satellite and
flowctl on `udp://` reaching TCP satellites as over any other transport (docs/protocol.md, "UDP")."""

import json
import socket
import subprocess

import pytest

from conftest import LEAN, PATIENCE, Agent, binary
from flow import Client


def free_udp_port() -> int:
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


@pytest.fixture
def udp_hub(tmp_path):
    port = free_udp_port()
    config = f'[server]\nflow_udp = "127.0.0.1:{port}"\n' + LEAN
    a = Agent(tmp_path / "data", config=config).start()
    yield a, f"udp://127.0.0.1:{port}"
    a.stop()


def test_a_python_satellite_over_udp_reaches_a_rust_subscriber(udp_hub):
    agent, addr = udp_hub
    client = Client.connect(addr, data_dir=str(agent.data_dir), name="py-udp")
    try:
        pub = client.publisher("Py.udp", {"format": "json"})
        echo = agent.flowctl("echo", "Py.udp", "--count", "3", "--json")
        assert pub.wait_subscribers(timeout=PATIENCE), "flowctl never subscribed"
        for i in range(3):
            pub.publish({"i": i, "over": "udp"})
        out, err = echo.communicate(timeout=PATIENCE)
        assert echo.returncode == 0, err.decode()
        rows = [json.loads(row) for row in out.decode().splitlines()]
        assert [r["json"] for r in rows] == [{"i": i, "over": "udp"} for i in range(3)]
    finally:
        client.close()


def test_flowctl_over_udp_publishes_to_a_python_subscriber(udp_hub):
    agent, addr = udp_hub
    client = Client.connect(agent.addr, data_dir=str(agent.data_dir), name="py-watcher")
    try:
        sub = client.subscribe("Rust.udp")
        lines = b"".join(json.dumps({"n": n}).encode() + b"\n" for n in range(5))
        proc = subprocess.run(
            [str(binary("flowctl")), "--addr", addr, "--data-dir", str(agent.data_dir),
             "pub", "Rust.udp", "--wait-subscriber"],
            input=lines, capture_output=True, timeout=PATIENCE,
        )
        assert proc.returncode == 0, proc.stderr.decode()
        got = [sub.recv(timeout=PATIENCE) for _ in range(5)]
        assert [m.json() for m in got] == [{"n": n} for n in range(5)]
    finally:
        client.close()
