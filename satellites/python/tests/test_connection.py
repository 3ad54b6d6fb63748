"""Connection life: a wrong or missing token is an AuthError, and a satellite survives the hub being killed and
restarted, its channels re-created and its subscriptions restored."""

import time

import pytest

from conftest import Agent, LEAN, PATIENCE, wait_until
from flow import AuthError, Client, ConnectionLost


def test_a_wrong_token_raises_auth_error(agent):
    with pytest.raises(AuthError):
        Client.connect(agent.addr, token="not-the-token")


def test_a_missing_token_file_names_the_file(agent, tmp_path):
    with pytest.raises(AuthError, match="token"):
        Client.connect(agent.addr, data_dir=str(tmp_path / "nowhere"))


def test_nothing_listening_is_a_connection_error():
    from conftest import free_port

    with pytest.raises(ConnectionLost, match="refused"):
        Client.connect(f"tcp://127.0.0.1:{free_port()}", token="x")


def test_channels_and_subscriptions_come_back_after_the_hub_is_killed_and_restarted(tmp_path):
    hub = Agent(tmp_path / "data", config=LEAN).start()
    try:
        client = Client.connect(hub.addr, data_dir=str(hub.data_dir), name="survivor")
        pub = client.publisher("Py.survivor")
        sub = client.subscribe("Rust.after")
        hub.kill()
        wait_until("the client to notice", lambda: not client.connected)
        hub = Agent(hub.data_dir, tcp_port=hub.tcp_port, config=LEAN).start()
        wait_until("the client to reconnect", lambda: client.connected)
        # Its subscription is back: a Rust publisher on the new hub reaches it.
        hub.flowctl_run("pub", "Rust.after", "--wait-subscriber", input=b'{"after": "restart"}\n')
        assert sub.recv(timeout=PATIENCE).json() == {"after": "restart"}
        # Its channel is back: a Rust subscriber on the new hub hears it.
        echo = hub.flowctl("echo", "Py.survivor", "--count", "1")
        assert pub.wait_subscribers(timeout=PATIENCE)
        pub.publish({"still": "here"})
        out, err = echo.communicate(timeout=PATIENCE)
        assert echo.returncode == 0, err.decode()
        assert out.decode().strip() == '{"still": "here"}'
        client.close()
        with pytest.raises(ConnectionLost):
            sub.recv(timeout=PATIENCE)
    finally:
        hub.stop()
