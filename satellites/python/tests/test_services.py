"""Service calls both ways between Python and Rust, with timeouts, a service whose owner dies, a handler that
raises, async handlers and awaitable calls."""

import asyncio
import json
import threading
import time

import pytest

from conftest import EXAMPLES, PATIENCE, wait_until
from flow import ChannelError, ServiceFailed, ServiceGone, agent as contract
from flow import TimeoutError as FlowTimeout


def test_python_calls_the_rust_speech_service_and_reads_its_typed_answer(client):
    answer = client.call(contract.SAY, {"text": "Hello from Python."}, timeout=PATIENCE)
    said = contract.SayAnswer.from_msg(answer)
    assert said.utterance >= 1


def test_rust_calls_a_python_service(agent, client):
    def double(request):
        return {"twice": request.json()["n"] * 2, "by": "python"}

    client.serve("Py.double", double, {"takes": {"n": "number"}})
    out = agent.flowctl_run("call", "Py.double", '{"n": 21}')
    assert json.loads(out) == {"twice": 42, "by": "python"}


def test_a_call_past_its_timeout_raises_the_flow_timeout(agent, client):
    def slow(_request):
        time.sleep(3)
        return "late"

    client.serve("Py.slow", slow)
    started = time.monotonic()
    with pytest.raises(FlowTimeout):
        client.call("Py.slow", {}, timeout=0.3)
    assert time.monotonic() - started < PATIENCE


def _dying_service(agent, client, tmp_path, name):
    """A Python satellite in its own process whose service exits the process on the first call, once listed."""
    script = tmp_path / f"{name}.py"
    script.write_text(
        "import os, sys, time\n"
        "from flow import Client\n"
        "c = Client.connect(name=sys.argv[1].replace('.', '-'))\n"
        "def handler(request):\n"
        "    os._exit(3)\n"
        "c.serve(sys.argv[1], handler)\n"
        "time.sleep(600)\n"
    )
    proc = agent.python(script, name)
    wait_until(f"the dying service {name}", lambda: any(c["name"] == name for c in client.channels()))
    return proc


def test_a_service_whose_owner_dies_mid_call_raises_service_gone(agent, client, tmp_path):
    proc = _dying_service(agent, client, tmp_path, "Py.dying")
    try:
        with pytest.raises(ServiceGone):
            client.call("Py.dying", {"please": "answer"}, timeout=PATIENCE)
    finally:
        proc.kill()
        proc.wait()


def test_a_handler_that_raises_is_a_service_failure_with_its_message(client):
    def refuse(_request):
        raise ValueError("no such direction: up")

    client.serve("Py.refuse", refuse)
    with pytest.raises(ServiceFailed, match="no such direction: up"):
        client.call("Py.refuse", {"direction": "up"}, timeout=PATIENCE)


def test_calling_a_service_nobody_offers_is_a_channel_error(client):
    with pytest.raises(ChannelError):
        client.call("Py.nobody", {}, timeout=PATIENCE)


def test_an_async_handler_answers_an_awaited_call(client):
    async def main():
        async def shout(request):
            await asyncio.sleep(0.01)
            return request.text().upper()

        # Served from inside the loop: the handler runs on it.
        service = client.serve("Py.shout", shout)
        try:
            answer = await client.call_async("Py.shout", "ciao", timeout=PATIENCE)
            return answer.text()
        finally:
            service.close()

    assert asyncio.run(main()) == "CIAO"


def test_a_closed_service_is_gone_for_callers(client):
    service = client.serve("Py.closing", lambda r: "yes")
    assert client.call("Py.closing", "?", timeout=PATIENCE).text() == "yes"
    service.close()
    wait_until("the service to go", lambda: not any(c["name"] == "Py.closing" for c in client.channels()))
    with pytest.raises(ChannelError):
        client.call("Py.closing", "?", timeout=PATIENCE)


def _rust_service(agent, client, name, *args):
    """`flowctl serve NAME ARGS` in the background, once the hub lists its service."""
    proc = agent.flowctl("serve", name, *args)
    wait_until(f"flowctl serving {name}", lambda: any(c["name"] == name for c in client.channels()))
    return proc


def test_python_calls_a_slow_rust_service_past_its_timeout_and_gets_the_flow_timeout(agent, client):
    proc = _rust_service(agent, client, "Rs.slow", "--delay-ms", "5000", "--reply", '{"late": true}')
    try:
        with pytest.raises(FlowTimeout):
            client.call("Rs.slow", {}, timeout=0.3)
    finally:
        proc.kill()
        proc.wait()


def test_python_gets_an_answer_from_a_rust_service_and_service_gone_when_it_dies_mid_call(agent, client):
    proc = _rust_service(agent, client, "Rs.dying", "--delay-ms", "60000", "--reply", '{"never": true}')
    quick = _rust_service(agent, client, "Rs.quick", "--reply", '{"ok": 1}')
    try:
        assert client.call("Rs.quick", {}, timeout=PATIENCE).json() == {"ok": 1}
        # The owner is killed while the call waits for its answer.
        killer = threading.Timer(0.5, proc.kill)
        killer.start()
        with pytest.raises(ServiceGone):
            client.call("Rs.dying", {"please": "answer"}, timeout=PATIENCE)
        killer.join()
    finally:
        for p in (proc, quick):
            p.kill()
            p.wait()


def test_rust_calls_a_slow_python_service_past_its_timeout_and_is_told_so(agent, client):
    def slow(_request):
        time.sleep(3)
        return "late"

    client.serve("Py.slow_for_rust", slow)
    proc = agent.flowctl("call", "Py.slow_for_rust", "{}", "--timeout-ms", "300")
    _, err = proc.communicate(timeout=PATIENCE)
    assert proc.returncode != 0
    assert "Timeout" in err.decode(), err.decode()


def test_rust_calls_a_python_service_whose_owner_dies_and_is_told_it_is_gone(agent, client, tmp_path):
    owner = _dying_service(agent, client, tmp_path, "Py.dying_for_rust")
    try:
        proc = agent.flowctl("call", "Py.dying_for_rust", "{}", "--timeout-ms", "20000")
        _, err = proc.communicate(timeout=PATIENCE)
        assert proc.returncode != 0
        assert "ServiceGone" in err.decode(), err.decode()
    finally:
        owner.kill()
        owner.wait()
