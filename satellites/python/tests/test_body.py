"""The end-to-end "turn left": with every module on, as `make run` starts them, a transcript "turn left" makes the
brain call Robot.command, which examples/body.py serves; its reply is spoken (a caption and speech PCM)."""

import subprocess

from conftest import EXAMPLES, PATIENCE, REPO, Agent, binary, recv_until, wait_subscribers, wait_until
from flow import Client, agent as contract


def test_turn_left_is_served_by_the_python_body_and_its_answer_is_spoken(tmp_path):
    hub = Agent(tmp_path / "data").start()  # the embedded default configuration: every module on
    body = hub.python(EXAMPLES / "body.py")
    try:
        with Client.connect(hub.addr, data_dir=str(hub.data_dir), name="ears", queue=4096) as client:
            wait_until("the body to serve", lambda: any(c["name"] == "Robot.command" for c in client.channels()))
            avatar = client.subscribe(contract.AVATAR)
            speech = client.subscribe(contract.SPEECH)
            transcript = client.publisher(contract.TRANSCRIPT, contract.HEADERS[contract.TRANSCRIPT])
            # The brain and the speech module (which stops speech when the user talks) both listen.
            wait_subscribers(client, contract.TRANSCRIPT, 2)
            transcript.publish({"text": "Turn left, please.", "final": True})
            # Agent.avatar is busy (blinks, gaze): only the one deadline ends a wait that never matches.
            command = recv_until(avatar, "the body's answer spoken (say 'Turning left...')",
                                 lambda c: c.cmd == "say" and "Turning left" in c.text, decode=contract.Avatar.from_msg)
            assert command.text == "Turning left. I now face 270 degrees."
            pcm = speech.recv(timeout=PATIENCE)
            assert len(pcm) > 8, "speech carries PCM after its utterance/offset prefix"
            assert client.db.get("robot.heading") == 270
    finally:
        body.kill()
        out = body.stdout.read().decode()
        body.wait()
        hub.stop()
    assert "body: turned left, heading 270 degrees" in out, out


def test_a_head_turning_request_reaches_the_python_body_through_the_models_forced_tool_call(tmp_path):
    """"Face the window" is no exact command: the default program's `move` rule hands it to the language model with
    `chat(T, "Robot.command")`, whose grammar lets it answer only with a valid call; the brain performs the call
    and the body's answer is spoken. Which way the model turns is its choice: the test holds the path, not the
    direction."""
    hub = Agent(tmp_path / "data").start()
    body = hub.python(EXAMPLES / "body.py")
    model = REPO / "models" / "llm" / "SmolLM2-135M-Instruct.Q4_1.gguf"
    llm = subprocess.Popen(
        [str(binary("llm-sat")), "--addr", hub.addr, "--data-dir", str(hub.data_dir), "--model", str(model)],
        stdin=subprocess.DEVNULL,
    )
    try:
        with Client.connect(hub.addr, data_dir=str(hub.data_dir), name="ears", queue=4096) as client:
            names = lambda: {c["name"] for c in client.channels()}  # noqa: E731
            wait_until("the body and the model to serve", lambda: {"Robot.command", contract.CHAT} <= names())
            avatar = client.subscribe(contract.AVATAR)
            replies = client.subscribe(contract.CHAT_REPLY)
            transcript = client.publisher(contract.TRANSCRIPT, contract.HEADERS[contract.TRANSCRIPT])
            wait_subscribers(client, contract.TRANSCRIPT, 2)
            transcript.publish({"text": "Please face the window.", "final": True})
            event = recv_until(replies, "the model's call (or the end of its turn)",
                               lambda e: e["event"] in ("call", "end"), decode=lambda m: m.json())
            assert event["event"] == "call", f"the turn ended without a call: {event}"
            assert event["call"]["service"] == "Robot.command"
            assert event["call"]["payload"]["action"] == "turn"
            assert event["call"]["payload"]["direction"] in ("left", "right")
            command = recv_until(avatar, "the body's answer spoken (say 'Turning ...')",
                                 lambda c: c.cmd == "say" and c.text.startswith("Turning "),
                                 decode=contract.Avatar.from_msg)
            direction = event["call"]["payload"]["direction"]
            assert command.text.startswith(f"Turning {direction}.")
    finally:
        llm.kill()
        llm.wait()
        body.kill()
        out = body.stdout.read().decode()
        body.wait()
        hub.stop()
    assert f"body: turned {direction}" in out, out
