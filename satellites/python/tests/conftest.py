"""Fixtures of the Python SDK's tests: a real robot-agent (the binary `make test` builds) in a fresh data directory
on free ports, flowctl as the Rust satellite, the shared recordings and pictures, and helpers that wait on events
with generous timeouts (never on wall-clock assertions), each wait under one overall deadline."""

from __future__ import annotations

import os
import re
import signal
import socket
import subprocess
import sys
import threading
import time
from pathlib import Path
from typing import Any, Callable, Optional

import pytest

REPO = Path(__file__).resolve().parents[3]
EXAMPLES = REPO / "satellites" / "python" / "examples"
#: How long any single expected event may take on a loaded two-core CI machine.
PATIENCE = 60.0


def bin_dir() -> Path:
    """Where the workspace's binaries are: $AGENT_BIN_DIR, else the debug build of $CARGO_TARGET_DIR or target/."""
    if os.environ.get("AGENT_BIN_DIR"):
        return Path(os.environ["AGENT_BIN_DIR"])
    target = Path(os.environ.get("CARGO_TARGET_DIR", REPO / "target"))
    return target / "debug"


def binary(name: str) -> Path:
    path = bin_dir() / name
    if not path.exists():
        pytest.fail(f"{path} is missing: build the workspace first (make build-debug) or set AGENT_BIN_DIR")
    return path


def fixtures() -> Path:
    found = os.environ.get("AGENT_FIXTURES") or str(REPO.parent / "shared" / "fixtures")
    path = Path(found)
    if not path.is_dir():
        pytest.fail(f"no shared fixtures at {path}: set AGENT_FIXTURES")
    return path


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def wait_until(what: str | Callable[[], str], check: Callable[[], object], timeout: float = PATIENCE):
    """Polls `check` until it returns something truthy; fails naming `what` after `timeout` (a callable `what` is
    asked then, so that it can say how things stood at the deadline: a process's output so far)."""
    deadline = time.monotonic() + timeout
    while True:
        got = check()
        if got:
            return got
        if time.monotonic() > deadline:
            pytest.fail(f"timed out after {timeout:g} s waiting for {what() if callable(what) else what}")
        time.sleep(0.02)


def short(value, limit: int = 160) -> str:
    """`repr(value)`, cut to `limit` characters for a failure message."""
    text = repr(value)
    return text if len(text) <= limit else text[: limit - 3] + "..."


def recv_until(sub, what: str, predicate: Callable[[Any], object], timeout: float = PATIENCE,
               decode: Callable[[Any], Any] = lambda msg: msg):
    """Receives from the subscription `sub` until `predicate` holds on a message (as `decode` makes it) and returns
    that message. The wait has one deadline, `timeout` from now, however busy the channel: each receive gets only
    the time left, so messages that never match (the avatar's blinks, say) cannot keep it going. Past the deadline
    it fails naming `what`, the channel, how many messages it saw and the last one."""
    __tracebackhide__ = True  # a failure points at the test's line
    from flow import TimeoutError as FlowTimeout

    deadline = time.monotonic() + timeout
    seen, last = 0, None
    while (left := deadline - time.monotonic()) > 0:
        try:
            msg = sub.recv(timeout=left)
        except FlowTimeout:
            break  # no message in the time left: that is the deadline
        seen += 1
        last = decode(msg)
        if predicate(last):
            return last
    pytest.fail(f"timed out after {timeout:g} s waiting for {what} on {sub.name}: {seen} messages, none matched"
                + (f"; the last: {short(last)}" if seen else ""))


def wait_subscribers(client, channel: str, count: int) -> None:
    """Waits until `channel` has at least `count` subscribers, as the hub counts them."""
    wait_until(
        f"{count} subscribers on {channel}",
        lambda: any(c["name"] == channel and c["subscribers"] >= count for c in client.channels()),
    )


def same(a, b) -> bool:
    """Equal JSON values, floats compared as the f32 the contract stores them in (seven significant digits)."""
    if isinstance(a, float) or isinstance(b, float):
        return isinstance(a, (int, float)) and isinstance(b, (int, float)) and abs(a - b) <= 1e-6 * max(1, abs(b))
    if isinstance(a, dict) and isinstance(b, dict):
        return a.keys() == b.keys() and all(same(a[k], b[k]) for k in a)
    if isinstance(a, list) and isinstance(b, list):
        return len(a) == len(b) and all(same(x, y) for x, y in zip(a, b))
    return a == b


def fits(sent, parsed) -> bool:
    """`parsed` (a contract type's canonical form) carries every field of `sent` unchanged (see `same`), and
    whatever it adds is a default: null, zero, false or empty."""
    if isinstance(sent, dict) and isinstance(parsed, dict):
        extra = parsed.keys() - sent.keys()
        return (sent.keys() <= parsed.keys() and all(fits(sent[k], parsed[k]) for k in sent)
                and all(parsed[k] in (None, 0, False, [], {}) for k in extra))
    if isinstance(sent, list) and isinstance(parsed, list):
        return len(sent) == len(parsed) and all(fits(x, y) for x, y in zip(sent, parsed))
    return same(sent, parsed)


class Output:
    """Lines a child process prints, collected by a thread so the pipe never fills."""

    def __init__(self, stream) -> None:
        self.lines: list[str] = []
        self._lock = threading.Lock()
        self._thread = threading.Thread(target=self._read, args=(stream,), daemon=True)
        self._thread.start()

    def _read(self, stream) -> None:
        for raw in iter(stream.readline, b""):
            with self._lock:
                self.lines.append(raw.decode("utf-8", "replace").rstrip("\n"))

    def snapshot(self) -> list[str]:
        with self._lock:
            return list(self.lines)

    def text(self) -> str:
        return "\n".join(self.snapshot())

    def wait_for(self, needle: str, timeout: float = PATIENCE) -> str:
        return wait_until(
            lambda: f"{needle!r} in the output:\n{self.text()}",
            lambda: next((l for l in self.snapshot() if needle in l), None),
            timeout,
        )


def start_hub_process(cmd: list[str], env: dict, cwd: Optional[Path] = None) -> tuple[subprocess.Popen, Output]:
    """Starts a process that serves a hub (robot-agent, flow-hub) and waits until it listens on its Unix socket."""
    name = Path(cmd[0]).name
    proc = subprocess.Popen(cmd, stdin=subprocess.DEVNULL, stdout=subprocess.PIPE, stderr=subprocess.STDOUT,
                            env=env, cwd=cwd)
    output = Output(proc.stdout)
    wait_until(
        lambda: f"{name} to listen:\n{output.text()}",
        lambda: proc.poll() is not None or any("flow hub: unix:" in l for l in output.snapshot()),
    )
    if proc.poll() is not None:
        pytest.fail(f"{name} exited at start ({proc.returncode}):\n{output.text()}")
    return proc, output


def stop_process(proc: subprocess.Popen) -> None:
    """SIGTERM, then SIGKILL if it has not ended within PATIENCE."""
    if proc.poll() is None:
        proc.send_signal(signal.SIGTERM)
        try:
            proc.wait(timeout=PATIENCE)
        except subprocess.TimeoutExpired:
            proc.kill()
            proc.wait()


class Agent:
    """A running robot-agent: its addresses, data directory and output."""

    def __init__(self, data_dir: Path, tcp_port: Optional[int] = None, config: str = "") -> None:
        self.data_dir = data_dir
        self.tcp_port = tcp_port or free_port()
        self.config = config
        self.proc: Optional[subprocess.Popen] = None
        self.output: Optional[Output] = None

    @property
    def addr(self) -> str:
        return f"tcp://127.0.0.1:{self.tcp_port}"

    @property
    def token(self) -> str:
        return (self.data_dir / "token").read_text().strip()

    def start(self) -> "Agent":
        cmd = [
            str(binary("robot-agent")),
            "--http", "127.0.0.1:0",
            "--flow-tcp", f"127.0.0.1:{self.tcp_port}",
            "--flow-unix", "flow.sock",
            "--data-dir", str(self.data_dir),
        ]
        if self.config:
            path = self.data_dir / "test-config.toml"
            self.data_dir.mkdir(parents=True, exist_ok=True)
            path.write_text(self.config)
            cmd += ["--config", str(path)]
        env = dict(os.environ, RUST_LOG=os.environ.get("AGENT_TEST_LOG", "info"), NO_COLOR="1")
        # From the repository root, as `make run` starts it: the default brain program is config/brain.tr.
        self.proc, self.output = start_hub_process(cmd, env, cwd=REPO)
        return self

    def kill(self) -> None:
        """SIGKILL: the hub vanishes without a goodbye, as in a crash."""
        if self.proc and self.proc.poll() is None:
            self.proc.kill()
            self.proc.wait(timeout=PATIENCE)

    def stop(self) -> None:
        if self.proc:
            stop_process(self.proc)

    def flowctl(self, *args: str, **popen) -> subprocess.Popen:
        """`flowctl --addr ... --data-dir ... ARGS` started in the background, output piped."""
        env = {k: v for k, v in os.environ.items() if k not in ("FLOW_ADDR", "FLOW_TOKEN", "ROBOT_AGENT_DATA")}
        return subprocess.Popen(
            [str(binary("flowctl")), "--addr", self.addr, "--data-dir", str(self.data_dir), *args],
            stdout=subprocess.PIPE, stderr=subprocess.PIPE, env=env, **popen,
        )

    def flowctl_run(self, *args: str, input: Optional[bytes] = None) -> str:
        """Runs flowctl to completion and returns its standard output (fails on a non-zero exit)."""
        proc = self.flowctl(*args, stdin=subprocess.PIPE if input is not None else subprocess.DEVNULL)
        out, err = proc.communicate(input=input, timeout=PATIENCE)
        if proc.returncode != 0:
            pytest.fail(f"flowctl {' '.join(args)} failed ({proc.returncode}): {err.decode()}")
        return out.decode()

    def python(self, script: Path, *args: str, **popen) -> subprocess.Popen:
        """A Python satellite of this agent in its own process, output piped."""
        env = dict(os.environ, FLOW_ADDR=self.addr, ROBOT_AGENT_DATA=str(self.data_dir), PYTHONUNBUFFERED="1")
        popen.setdefault("stderr", subprocess.STDOUT)
        return subprocess.Popen([sys.executable, str(script), *args], stdout=subprocess.PIPE, env=env, **popen)


#: Only what the Python tests exercise besides the hub: the brain and the speech it answers with. The camera
#: modules have no camera here and only cost start-up time.
LEAN = """
[modules.vision]
enabled = false
"""


@pytest.fixture
def agent(tmp_path):
    a = Agent(tmp_path / "data", config=LEAN).start()
    yield a
    a.stop()


@pytest.fixture
def client(agent):
    from flow import Client

    c = Client.connect(agent.addr, data_dir=str(agent.data_dir), name="pytest", queue=1024)
    yield c
    c.close()
