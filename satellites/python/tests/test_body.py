"""The end-to-end "turn left": with every module on, as `make run` starts them, a transcript "turn left" makes the
brain call Robot.command, which examples/body.py serves; its reply is spoken (a caption and speech PCM)."""

from conftest import EXAMPLES, PATIENCE, Agent, wait_subscribers, wait_until
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
            while True:
                command = contract.Avatar.from_msg(avatar.recv(timeout=PATIENCE))
                if command.cmd == "say" and "Turning left" in command.text:
                    break
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
