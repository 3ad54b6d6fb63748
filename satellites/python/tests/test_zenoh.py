"""Any Zenoh client joins the federation (docs/federation.md): a plain `eclipse-zenoh` session, knowing nothing of
FlowProtocol, subscribes to `flow/*/Agent.transcript` of a real robot-agent and publishes into a channel the agent
imports; the agent's side is the Python SDK."""

from __future__ import annotations

import json
import queue
import time

import pytest

from conftest import LEAN, PATIENCE, Agent, free_port, wait_until

zenoh = pytest.importorskip("zenoh", reason="eclipse-zenoh is installed by scripts/python-sdk.sh")


def federated_agent(tmp_path, port: int) -> Agent:
    from flow import agent as contract

    config = LEAN + f"""
[federation]
enabled = true
name = "robot"
listen = ["tcp/127.0.0.1:{port}"]
export = ["{contract.TRANSCRIPT}"]
import = ["Robot.*"]
lease_ms = 1000
"""
    agent = Agent(tmp_path / "data", config=config).start()
    agent.output.wait_for("federation joined the Zenoh network")
    return agent


def zenoh_client(port: int):
    config = zenoh.Config()
    config.insert_json5("mode", '"client"')
    config.insert_json5("connect/endpoints", json.dumps([f"tcp/127.0.0.1:{port}"]))
    config.insert_json5("scouting/multicast/enabled", "false")
    return zenoh.open(config)


def test_a_plain_zenoh_client_reads_transcripts_and_publishes_into_an_imported_channel(tmp_path):
    import flow
    from flow import Client
    from flow import agent as contract

    port = free_port()
    agent = federated_agent(tmp_path, port)
    try:
        hub = Client.connect(agent.addr, data_dir=str(agent.data_dir), name="pytest", queue=1024)
        transcripts = hub.publisher(contract.TRANSCRIPT, {"mime": "application/json"})
        with zenoh_client(port) as z:
            heard: "queue.Queue[tuple[str, bytes]]" = queue.Queue()
            sub = z.declare_subscriber(
                f"flow/*/{contract.TRANSCRIPT}",
                lambda sample: heard.put((str(sample.key_expr), bytes(sample.payload.to_bytes()))),
            )
            # (The agent's own brain and observer listen to transcripts too, so the producer always has subscribers
            # here; tests/federation.rs checks that a remote listener alone switches a producer on and off.)
            sent = {"text": "what time is it", "utterance": "u1", "satellite": "pytest"}
            deadline = time.monotonic() + PATIENCE
            key, payload = None, None
            while time.monotonic() < deadline:
                transcripts.publish(sent)
                try:
                    key, payload = heard.get(timeout=0.2)
                    break
                except queue.Empty:
                    continue
            assert key == f"flow/robot/{contract.TRANSCRIPT}"
            assert json.loads(payload) == sent
            sub.undeclare()

            # The other way: announce a stream the way hubs do (a liveliness token), then put on its key.
            token = z.liveliness().declare_token("flow/@flow/py/stream/Robot.command")
            commands = hub.subscribe("Robot.command")
            wait_until("the imported channel", lambda: any(c["name"] == "Robot.command" for c in hub.channels()))
            got = None
            deadline = time.monotonic() + PATIENCE
            while got is None and time.monotonic() < deadline:
                z.put("flow/py/Robot.command", json.dumps({"action": "turn", "direction": "left"}))
                try:
                    got = commands.recv(timeout=0.2)
                except flow.TimeoutError:
                    continue
            assert got is not None, "the put never reached the hub's subscriber"
            assert got.json() == {"action": "turn", "direction": "left"}
            owner = next(c["owner"] for c in hub.channels() if c["name"] == "Robot.command")
            assert owner.startswith("federation#")
            token.undeclare()
            wait_until(
                "the import to go with its announcement",
                lambda: not any(c["name"] == "Robot.command" for c in hub.channels()),
            )
        hub.close()
    finally:
        agent.stop()
