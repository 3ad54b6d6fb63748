"""Benchmark of the Python SDK (`flow`): a Python subscriber's throughput and CPU per message against redis-py pub/sub
in the same run, 1 MB frames to a Python subscriber by shared memory (the Unix socket) against its TCP path, and the
jitter of a Python `flow.Sketch` at 100 Hz; prints SUMMARY lines and writes a markdown report
(`--write docs/bench-python.md`).

    satellites/python/.venv/bin/python bench/python/bench_python.py --write docs/bench-python.md
    satellites/python/.venv/bin/python bench/python/bench_python.py --shm-only   # the shared-memory phase alone

It starts its own `flow-hub` (from $AGENT_BIN_DIR, else the release or debug build in $CARGO_TARGET_DIR or
./target) and its own `redis-server` on free ports, and always stops both. Every publisher and subscriber is a
separate Python process (multiprocessing, spawn), so each subscriber's CPU figure is its own process's alone.
"""

from __future__ import annotations

import argparse
import ctypes
import math
import multiprocessing as mp
import os
import platform
import resource
import shutil
import signal
import socket
import statistics
import subprocess
import sys
import tempfile
import threading
import time
import wave
from dataclasses import dataclass, field
from pathlib import Path
from typing import Optional

REPO = Path(__file__).resolve().parents[2]

# The hub's own per-subscriber lane is 64 messages (config/default.toml, hub.subscriber_queue): a window of 32 keeps
# every run lossless on both systems, as hub-bench's window mode does, so the rate is what the subscriber can take,
# not what a queue threw away. Redis never sees more than 32 messages buffered for the subscriber either, so its
# output-buffer limit (which disconnects a slow pub/sub client) never comes into play.
WINDOW = 32
# redis-py's publish() waits for the server's reply, one round trip per message; pipelining a few per round trip is
# how a Redis producer goes fast, and keeps Redis's figure the subscriber's rather than its publisher's round trips.
REDIS_BATCH = 8
# redis-py 8 speaks RESP3 by default, where a pub/sub message is a push reply that its parser first turns into a
# string for a debug log line (redis/_parsers/hiredis.py, handle_pubsub_push_response), even with logging off: about
# 0.5 ms per JPEG, a redis-py bug that would flatter flow. RESP2, the protocol of every redis-py before 8, has no such
# cost, so the baseline is redis-py at its best.
REDIS_PROTOCOL = 2
# The flow client's local queue (Client.connect(queue=...)): deeper than the window, so it never drops either.
FLOW_QUEUE = 256

PCM_RATE = 22050
PCM_CHUNK = 441  # 20 ms of s16 mono at 22050 Hz: 882 bytes, as on Agent.audio

# The shared-memory phase: 1 MB frames (about a 640x480 RGB24 picture, the size shared memory is for) from a Python
# publisher to a Python subscriber, both on the hub's Unix socket (the frame goes by reference: copied once into the
# publisher's segment, read in place by the subscriber) or both over TCP (copied through both sockets).
SHM_FRAME = 1 << 20
# Four frames in flight at most: over TCP the hub's per-subscriber lane holds 8 MB (hub.subscriber_queue_bytes), and
# a window of 32 megabyte frames would have it drop the oldest, so the TCP figure would be what survived a queue.
SHM_WINDOW = 4
SHM_TARGET = 5.0


# ---------------------------------------------------------------------------------------------------- payloads


def fixtures_dir() -> Path:
    env = os.environ.get("AGENT_FIXTURES")
    if env:
        return Path(env)
    # Same fallback as scripts/fixtures.sh: the shared fixtures beside the repository, then the workplace's copy.
    for candidate in (REPO.parent / "shared" / "fixtures", Path("/work/shared/fixtures")):
        if candidate.is_dir():
            return candidate
    raise SystemExit("bench_python: no fixtures (set AGENT_FIXTURES)")


def jpeg_payload(fixtures: Path) -> tuple[bytes, str]:
    # The same real 640x360 camera-format JPEG hub-bench uses (bench/hub/payloads.rs).
    path = fixtures / "faces/derived/fr_two_people_640x360.jpg"
    data = path.read_bytes()
    if not data.startswith(b"\xff\xd8"):
        raise SystemExit(f"bench_python: {path} is not a JPEG")
    return data, str(path.relative_to(fixtures))


def pcm_payload(fixtures: Path) -> tuple[bytes, str]:
    # 20 ms of real speech, one second into the clip where the speaker talks (as hub-bench cuts it).
    path = fixtures / "audio/LJ001-0001.wav"
    with wave.open(str(path), "rb") as w:
        if (w.getframerate(), w.getnchannels(), w.getsampwidth()) != (PCM_RATE, 1, 2):
            raise SystemExit(f"bench_python: {path} is not s16 mono {PCM_RATE} Hz")
        w.setpos(PCM_RATE)
        data = w.readframes(PCM_CHUNK)
    if len(data) != PCM_CHUNK * 2:
        raise SystemExit(f"bench_python: {path} is shorter than 1 s + 20 ms")
    return data, str(path.relative_to(fixtures))


# ---------------------------------------------------------------------------------------------------- servers


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def hub_binary() -> Path:
    dirs = []
    if os.environ.get("AGENT_BIN_DIR"):
        dirs.append(Path(os.environ["AGENT_BIN_DIR"]))
    target = Path(os.environ.get("CARGO_TARGET_DIR") or REPO / "target")
    dirs += [target / "release", target / "debug"]
    for d in dirs:
        if (d / "flow-hub").is_file():
            return d / "flow-hub"
    raise SystemExit(
        "bench_python: no flow-hub binary in " + ", ".join(map(str, dirs)) + " (cargo build --release -p flow-hub)"
    )


def stop(proc: Optional[subprocess.Popen]) -> None:
    """SIGTERM, then SIGKILL if it has not gone within 5 s."""
    if proc is None or proc.poll() is not None:
        return
    proc.terminate()
    try:
        proc.wait(5)
    except subprocess.TimeoutExpired:
        proc.kill()
        proc.wait()


@dataclass
class Hub:
    proc: subprocess.Popen
    addr: str
    data_dir: Path
    binary: Path
    unix: str  # "unix:PATH", the hub's Unix socket (shared memory goes there)


def start_hub(data_dir: Path) -> Hub:
    binary = hub_binary()
    # No HTTP page is needed (HTTP takes a free port since the hub always serves it); the Unix socket, in the data
    # directory, is the shared-memory phase's.
    proc = subprocess.Popen(
        [str(binary), "--http", "127.0.0.1:0", "--flow-tcp", "127.0.0.1:0", "--flow-unix", "flow.sock", "--data-dir",
         str(data_dir)],
        stdin=subprocess.DEVNULL,
        stdout=subprocess.PIPE,
        stderr=subprocess.STDOUT,
        text=True,
        env={**os.environ, "RUST_LOG": "warn", "NO_COLOR": "1"},
    )
    lines: list[str] = []
    deadline = time.monotonic() + 30
    addr = unix = None
    assert proc.stdout is not None
    # The hub prints its TCP address, then its socket's.
    while time.monotonic() < deadline and unix is None:
        line = proc.stdout.readline()
        if not line:
            break
        lines.append(line.rstrip())
        if line.startswith("flow hub: tcp://"):
            addr = line.split()[2]  # "tcp://127.0.0.1:PORT", as Client.connect takes it
        elif line.startswith("flow hub: unix:"):
            unix = line.split()[2]  # "unix:PATH"
    if addr is None or unix is None:
        stop(proc)
        raise SystemExit("bench_python: flow-hub did not start:\n" + "\n".join(lines))
    # Keep reading its output so a chatty hub never blocks on a full pipe.
    threading.Thread(target=lambda: [None for _ in proc.stdout], daemon=True).start()  # type: ignore[union-attr]
    return Hub(proc, addr, data_dir, binary, unix)


def start_redis(work: Path) -> tuple[subprocess.Popen, int, str]:
    binary = shutil.which("redis-server")
    if binary is None:
        raise SystemExit("bench_python: redis-server not found (apt-get install redis-server)")
    port = free_port()
    proc = subprocess.Popen(
        [binary, "--port", str(port), "--bind", "127.0.0.1", "--save", "", "--appendonly", "no", "--dir", str(work),
         "--logfile", str(work / "redis.log")],
        stdin=subprocess.DEVNULL,
        stdout=subprocess.DEVNULL,
        stderr=subprocess.DEVNULL,
    )
    deadline = time.monotonic() + 10
    while time.monotonic() < deadline:
        if proc.poll() is not None:
            raise SystemExit(f"bench_python: redis-server exited at start (see {work / 'redis.log'})")
        try:
            with socket.create_connection(("127.0.0.1", port), timeout=0.2) as s:
                s.sendall(b"PING\r\n")
                if s.recv(16).startswith(b"+PONG"):
                    break
        except OSError:
            time.sleep(0.05)
    else:
        stop(proc)
        raise SystemExit("bench_python: redis-server did not answer PING")
    version = subprocess.run([binary, "--version"], capture_output=True, text=True).stdout.split()
    ver = next((v.split("=", 1)[1] for v in version if v.startswith("v=")), "?")
    return proc, port, ver


# ---------------------------------------------------------------------------------------------------- children
# Each runs in its own spawned process; `acked` is the subscriber's received count, shared memory the publisher reads
# to stay within WINDOW; `done` tells the publisher to stop.


def cpu_s() -> float:
    ru = resource.getrusage(resource.RUSAGE_SELF)
    return ru.ru_utime + ru.ru_stime


def measure_loop(messages, acked, done, warmup: float, duration: float, on_msg) -> dict:
    """Counts `messages` (an iterator) for `warmup` + `duration` seconds; the figures are the measured part only."""
    n = 0
    start = time.monotonic()
    t_mark = start + warmup
    t_end = t_mark + duration
    n0 = c0 = t0 = None
    for m in messages:
        on_msg(m)
        n += 1
        acked.value = n
        now = time.monotonic()
        if n0 is None:
            if now >= t_mark:
                n0, c0, t0 = n, cpu_s(), now
        elif now >= t_end:
            c1 = cpu_s()
            done.value = 1
            return {"msgs": n - n0, "secs": now - t0, "cpu_s": c1 - c0}
    raise RuntimeError("the subscription ended early")


def flow_sub(addr, data_dir, channel, acked, done, ready, results, warmup, duration, expect=None) -> None:
    import flow

    with flow.Client.connect(addr, data_dir=data_dir, name="bench-sub", queue=FLOW_QUEUE) as client:
        sub = client.subscribe(channel)
        ready.set()
        gaps = [0]
        size = [0]
        shared = [0]  # messages that came by reference (shared memory), counted in the shared-memory phase only
        checked = [False]

        def on_msg(m):
            # Touch the payload as a consumer would (a zero-copy view), and count what the hub or queue lost.
            size[0] = len(memoryview(m))
            gaps[0] += m.gap

        def on_frame(m):
            on_msg(m)
            shared[0] += m.in_shared_memory
            if not checked[0]:
                # Once: the bytes are the publisher's.
                if m.bytes() != expect:
                    raise RuntimeError(f"{channel}: the payload differs from what was published")
                checked[0] = True

        out = measure_loop(sub, acked, done, warmup, duration, on_msg if expect is None else on_frame)
        out.update(gap=gaps[0], dropped=sub.dropped, size=size[0], shared=shared[0], seen=int(acked.value))
        results.put(out)


def flow_pub(addr, data_dir, channel, payload, acked, done, ready, results, window=WINDOW, loan=False) -> None:
    """Publishes `payload` as fast as the window allows; with `loan`, written into a loaned shared-memory slot
    wherever the link gives one (`Publisher.loan`: one copy, into the memory the subscriber reads), else published."""
    import flow

    with flow.Client.connect(addr, data_dir=data_dir, name="bench-pub") as client:
        pub = client.publisher(channel)
        if not pub.wait_subscribers(timeout=10):
            raise RuntimeError("no subscriber arrived")
        ready.set()
        sent = 0
        loaned = 0
        while not done.value:
            if sent - acked.value >= window:
                time.sleep(0.00005)
                continue
            slot = pub.loan(len(payload)) if loan else None
            if slot is not None:
                with memoryview(slot) as view:
                    view[:] = payload
                slot.publish()
                loaned += 1
            else:
                pub.publish(payload)
            sent += 1
        results.put({"sent": sent, "skipped": pub.skipped, "loaned": loaned})


def redis_sub(port, channel, acked, done, ready, results, warmup, duration) -> None:
    import redis

    r = redis.Redis(port=port, protocol=REDIS_PROTOCOL)
    p = r.pubsub(ignore_subscribe_messages=True)
    # The publisher waits until the server counts this subscription (PUBSUB NUMSUB), so nothing is published into
    # the void.
    p.subscribe(channel)
    ready.set()
    size = [0]

    def messages():
        for m in p.listen():
            if m["type"] == "message":
                yield m

    def on_msg(m):
        size[0] = len(memoryview(m["data"]))

    out = measure_loop(messages(), acked, done, warmup, duration, on_msg)
    out.update(gap=0, dropped=0, size=size[0])
    p.close()
    results.put(out)


def redis_pub(port, channel, payload, acked, done, ready, results) -> None:
    import redis

    r = redis.Redis(port=port, protocol=REDIS_PROTOCOL)
    while r.pubsub_numsub(channel)[0][1] == 0:
        time.sleep(0.01)
    ready.set()
    sent = 0
    pipe = r.pipeline(transaction=False)
    while not done.value:
        room = WINDOW - (sent - acked.value)
        if room <= 0:
            time.sleep(0.00005)
            continue
        for _ in range(min(room, REDIS_BATCH)):
            pipe.publish(channel, payload)
        sent += len(pipe.execute())
    results.put({"sent": sent, "skipped": 0})


# ---------------------------------------------------------------------------------------------------- sketch


def sketch_child(addr, data_dir, channel, seconds, results) -> None:
    import flow

    class Ticker(flow.Sketch):
        """100 Hz fast tick that records when each call happens, plus a 50 Hz PCM subscription as a voice sketch has."""

        fast_ms = 10.0

        def setup(self):
            self.subscribe(channel)
            self.period = self.fast_ms / 1000.0
            self.want = int(seconds / self.period)
            self.times: list[float] = []
            self.messages = 0
            # Run() makes the Events (whose timer starts then) right after setup returns: the ideal schedule starts
            # one period after this instant, a few microseconds early, so the lateness measured is if anything high.
            self.origin = time.monotonic()

        def fast_tick(self):
            self.times.append(time.monotonic())
            if len(self.times) >= self.want:
                self.stop()

        def on_message(self, channel, msg):
            self.messages += 1

        def teardown(self):
            self.rust = self.jitter()

    t = Ticker(addr=addr, data_dir=data_dir, name="bench-sketch")
    t.run()
    # Lateness of each call against the slot it serves; the pulses skip missed slots (as tokio's MissedTickBehavior::Skip),
    # so after a call later than a whole period the next ideal slot is the next one after that call.
    late, missed, k = [], 0, 1
    for now in t.times:
        ideal = t.origin + k * t.period
        late.append(max(0.0, now - ideal))
        nxt = max(k + 1, math.floor((now - t.origin) / t.period) + 1)
        missed += nxt - k - 1
        k = nxt
    results.put({"late_s": late, "missed": missed, "rust": t.rust, "messages": t.messages})


def paced_pub(addr, data_dir, channel, payload, hz, done) -> None:
    import flow

    with flow.Client.connect(addr, data_dir=data_dir, name="bench-audio") as client:
        pub = client.publisher(channel)
        pub.wait_subscribers(timeout=10)
        t = time.monotonic()
        while not done.value:
            pub.publish(payload)
            t += 1.0 / hz
            time.sleep(max(0.0, t - time.monotonic()))


# ---------------------------------------------------------------------------------------------------- orchestration

CTX = mp.get_context("spawn")


def run_pair(system: str, hub: Hub, redis_port: Optional[int], payload: bytes, channel: str, warmup: float,
             duration: float, addr: Optional[str] = None, window: int = WINDOW,
             expect: Optional[bytes] = None, loan: bool = False) -> dict:
    """One publisher and one subscriber process of `system`; flow's both connect to `addr` (default: the hub's TCP
    address) and keep within `window`; `expect` makes the subscriber check its first payload against it."""
    acked = CTX.RawValue(ctypes.c_uint64, 0)
    done = CTX.RawValue(ctypes.c_int, 0)
    sub_ready, pub_ready = CTX.Event(), CTX.Event()
    sub_q, pub_q = CTX.Queue(), CTX.Queue()
    if system == "flow":
        addr = addr or hub.addr
        sub = CTX.Process(target=flow_sub, args=(addr, str(hub.data_dir), channel, acked, done, sub_ready, sub_q,
                                                 warmup, duration, expect))
        pub = CTX.Process(target=flow_pub, args=(addr, str(hub.data_dir), channel, payload, acked, done, pub_ready,
                                                 pub_q, window, loan))
    else:
        sub = CTX.Process(target=redis_sub, args=(redis_port, channel, acked, done, sub_ready, sub_q, warmup,
                                                  duration))
        pub = CTX.Process(target=redis_pub, args=(redis_port, channel, payload, acked, done, pub_ready, pub_q))
    started = []
    try:
        sub.start()
        started.append(sub)
        wait_ready(sub, sub_ready, f"{system} subscriber")
        pub.start()
        started.append(pub)
        out = sub_q.get(timeout=30 + warmup + duration)
        out.update(pub_q.get(timeout=10))
        return out
    finally:
        done.value = 1
        for p in started:
            p.join(5)
            if p.is_alive():
                p.kill()
                p.join()


def wait_ready(proc, ready, what: str) -> None:
    """Waits for a child's ready event, failing at once (rather than after the timeout) if the child died."""
    deadline = time.monotonic() + 20
    while not ready.wait(0.1):
        if not proc.is_alive() or time.monotonic() > deadline:
            raise RuntimeError(f"{what} did not start (exit code {proc.exitcode})")


def shm_frame() -> bytes:
    """A deterministic 1 MB frame that compresses like noise (no page of it is all zeros)."""
    import random

    return random.Random(39).randbytes(SHM_FRAME)


def run_shm(hub: Hub, rounds: int, warmup: float, duration: float) -> dict:
    """1 MB frames to a Python subscriber over the Unix socket (shared memory) and over TCP, the transports in turn
    within each round; the rounds of each, by transport."""
    frame = shm_frame()
    out: dict = {"unix": [], "tcp": []}
    for i in range(rounds):
        order = ["unix", "tcp"] if i % 2 == 0 else ["tcp", "unix"]
        for transport in order:
            addr = hub.unix if transport == "unix" else hub.addr
            # Over the Unix socket the producer writes each frame into a loaned slot, as the Rust shm-bench's does;
            # over TCP there is no slot to loan and it publishes.
            r = run_pair("flow", hub, None, frame, f"bench.shm.{transport}.{i}", warmup, duration, addr=addr,
                         window=SHM_WINDOW, expect=frame, loan=transport == "unix")
            if r["size"] != SHM_FRAME:
                raise RuntimeError(f"{transport} delivered {r['size']} bytes, not {SHM_FRAME}")
            out[transport].append(r)
            print(f"  round {i + 1} 1MB  flow {transport:4} {'(shm)' if transport == 'unix' else '     '}: "
                  f"{rate(r):8.0f} msg/s  {us_per_msg(r):6.1f} us cpu/msg  (by reference {by_reference(r):.0%}, "
                  f"loaned {r.get('loaned', 0)} of {r.get('sent', 0)} sent, "
                  f"gap {r['gap']}, dropped {r['dropped']})", flush=True)
    return out


def by_reference(r: dict) -> float:
    """The share of a subscriber's messages that came in shared memory."""
    return r["shared"] / r["seen"] if r["seen"] else 0.0


def median_round(rounds: list) -> dict:
    # The round with the median rate, as Row.median: its CPU figure belongs to the same round.
    rs = sorted(rounds, key=rate)
    return rs[len(rs) // 2]


def shm_summary(shm: dict) -> tuple[str, str, float]:
    """The phase's SUMMARY line, its TARGET line and the ratio."""
    u, t = median_round(shm["unix"]), median_round(shm["tcp"])
    ratio = rate(u) / rate(t)
    drops = {k: sum(x["gap"] + x["dropped"] for x in v) for k, v in shm.items()}
    line = (f"SUMMARY python-shm 1MB unix(shm)={rate(u):.0f} msg/s tcp={rate(t):.0f} msg/s ratio={ratio:.2f} "
            f"(target >= {SHM_TARGET}) cpu/msg unix={us_per_msg(u):.1f} us tcp={us_per_msg(t):.1f} us "
            f"by-reference unix={by_reference(u):.0%} tcp={by_reference(t):.0%} "
            f"written-in-a-loan unix={u.get('loaned', 0) / max(u.get('sent', 0), 1):.0%} "
            f"drops unix={drops['unix']} tcp={drops['tcp']}")
    target = f"TARGET python-shm 1MB >= {SHM_TARGET}x TCP: {'met' if ratio >= SHM_TARGET else 'MISSED'}"
    return line, target, ratio


def shm_only(args) -> int:
    work = Path(tempfile.mkdtemp(prefix="bench-python-shm-"))
    hub_proc = None
    signal.signal(signal.SIGTERM, interrupt)
    try:
        hub = start_hub(work)
        hub_proc = hub.proc
        print(f"flow-hub {hub.binary} at {hub.addr} and {hub.unix}; 1 MB frames, window {SHM_WINDOW}, "
              f"{args.rounds} rounds x {args.duration} s (+{args.warmup} s warm-up)", flush=True)
        shm = run_shm(hub, args.rounds, args.warmup, args.duration)
    except KeyboardInterrupt:
        print("bench_python: interrupted", file=sys.stderr)
        return 130
    finally:
        stop(hub_proc)
        shutil.rmtree(work, ignore_errors=True)
    line, target, _ = shm_summary(shm)
    print(line)
    print(target)
    return 0


def run_sketch(hub: Hub, pcm: bytes, seconds: float) -> dict:
    done = CTX.RawValue(ctypes.c_int, 0)
    q = CTX.Queue()
    channel = "bench.sketch.audio"
    feeder = CTX.Process(target=paced_pub, args=(hub.addr, str(hub.data_dir), channel, pcm, 50.0, done))
    sketch = CTX.Process(target=sketch_child, args=(hub.addr, str(hub.data_dir), channel, seconds, q))
    try:
        feeder.start()
        sketch.start()
        return q.get(timeout=seconds + 30)
    finally:
        done.value = 1
        for p in (sketch, feeder):
            p.join(5)
            if p.is_alive():
                p.kill()
                p.join()


# A satellite blocked in `for msg in sub` (or in `call`) on a channel nothing publishes; Ctrl-C must reach it as
# KeyboardInterrupt, which it reports with the monotonic clock the parent read when it sent the signal.
SIGINT_CHILD = """
import sys, time
from flow import Client
c = Client.connect(sys.argv[1], data_dir=sys.argv[2], name="bench-sigint")
mode = sys.argv[3]
print("waiting", flush=True)
try:
    if mode == "recv":
        for _ in c.subscribe("bench.sigint.silent"):
            pass
    else:
        c.call("bench.sigint.sleepy", {}, timeout=600)
except KeyboardInterrupt:
    print("interrupted", time.monotonic(), flush=True)
"""


# The service the blocked call waits on, in a process of its own; it never answers.
SLEEPY_SERVICE = """
import sys, time
from flow import Client
c = Client.connect(sys.argv[1], data_dir=sys.argv[2], name="bench-sigint-service")
svc = c.serve("bench.sigint.sleepy", lambda r: time.sleep(600))
print("serving", flush=True)
time.sleep(3600)
"""


def run_sigint(hub: Hub, tries: int) -> dict:
    """Time from SIGINT to KeyboardInterrupt in a process blocked in recv or in a call, `tries` times each."""
    out = {"recv": [], "call": []}
    service = subprocess.Popen([sys.executable, "-c", SLEEPY_SERVICE, hub.addr, str(hub.data_dir)],
                               stdout=subprocess.PIPE, text=True)
    try:
        if service.stdout.readline().strip() != "serving":
            raise RuntimeError("the sleepy service did not start")
        measure_sigint(hub, tries, out)
    finally:
        service.kill()
        service.wait()
    return out


def measure_sigint(hub: Hub, tries: int, out: dict) -> None:
    for mode in out:
        for _ in range(tries):
            proc = subprocess.Popen([sys.executable, "-c", SIGINT_CHILD, hub.addr, str(hub.data_dir), mode],
                                    stdout=subprocess.PIPE, text=True)
            try:
                if proc.stdout.readline().strip() != "waiting":
                    raise RuntimeError(f"the SIGINT child ({mode}) did not start")
                time.sleep(0.3)  # let it block inside the wait
                sent = time.monotonic()
                proc.send_signal(signal.SIGINT)
                line = proc.stdout.readline().split()
                if not line or line[0] != "interrupted":
                    raise RuntimeError(f"the SIGINT child ({mode}) said {line!r}")
                out[mode].append((float(line[1]) - sent) * 1e3)
            finally:
                proc.kill()
                proc.wait()


def sigint_only() -> int:
    work = Path(tempfile.mkdtemp(prefix="bench-python-sigint-"))
    hub_proc = None
    try:
        hub = start_hub(work)
        hub_proc = hub.proc
        sig = run_sigint(hub, 10)
    finally:
        stop(hub_proc)
        shutil.rmtree(work, ignore_errors=True)
    every = sig["recv"] + sig["call"]
    print(f"SUMMARY python-sigint KeyboardInterrupt after SIGINT recv p50={pct(sig['recv'], 0.5):.1f} ms "
          f"max={max(sig['recv']):.1f} ms call p50={pct(sig['call'], 0.5):.1f} ms max={max(sig['call']):.1f} ms "
          f"(target <= 100 ms)")
    print(f"TARGET python-sigint every Ctrl-C within 100 ms: {'met' if max(every) <= 100.0 else 'MISSED'}")
    return 0


def pct(values: list[float], q: float) -> float:
    s = sorted(values)
    return s[min(len(s) - 1, max(0, math.ceil(q * len(s)) - 1))]


@dataclass
class Row:
    name: str
    size: int
    target: float
    rounds: dict = field(default_factory=lambda: {"flow": [], "redis": []})

    def median(self, system: str) -> dict:
        # The round with the median rate, as hub-bench reports: its CPU figure belongs to the same round.
        rs = sorted(self.rounds[system], key=lambda r: r["msgs"] / r["secs"])
        return rs[len(rs) // 2]


def rate(r: dict) -> float:
    return r["msgs"] / r["secs"]


def us_per_msg(r: dict) -> float:
    return r["cpu_s"] / r["msgs"] * 1e6


def interrupt(*_) -> None:
    raise KeyboardInterrupt


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--duration", type=float, default=2.0, help="measured seconds per round and system (default 2)")
    ap.add_argument("--warmup", type=float, default=0.5, help="seconds discarded before measuring (default 0.5)")
    ap.add_argument("--rounds", type=int, default=3, help="rounds per payload, systems in turn (default 3)")
    ap.add_argument("--jitter-seconds", type=float, default=10.0, help="length of the Sketch run (default 10)")
    ap.add_argument("--write", type=Path, help="write the markdown report here (e.g. docs/bench-python.md)")
    ap.add_argument("--sigint-only", action="store_true",
                    help="only time Ctrl-C into blocked satellites (needs no Redis; writes no report)")
    ap.add_argument("--shm-only", action="store_true",
                    help="only the shared-memory phase, 1 MB frames over the Unix socket vs TCP (needs no Redis; "
                         "writes no report)")
    args = ap.parse_args()
    if args.sigint_only:
        return sigint_only()
    if args.shm_only:
        return shm_only(args)
    args.load = os.getloadavg()[0]

    import redis  # noqa: F401  (fail early, before starting servers, if redis-py is missing)

    fixtures = fixtures_dir()
    jpeg, jpeg_src = jpeg_payload(fixtures)
    pcm, pcm_src = pcm_payload(fixtures)
    rows = [Row("jpeg", len(jpeg), 2.0), Row("pcm", len(pcm), 1.5)]
    payloads = {"jpeg": jpeg, "pcm": pcm}

    work = Path(tempfile.mkdtemp(prefix="bench-python-"))
    hub_proc = redis_proc = None
    # SIGTERM (e.g. make interrupted from another shell) unwinds like Ctrl-C, through the finally below.
    signal.signal(signal.SIGTERM, interrupt)
    try:
        (work / "hub").mkdir()
        hub = start_hub(work / "hub")
        hub_proc = hub.proc
        redis_proc, redis_port, redis_ver = start_redis(work)
        print(f"flow-hub {hub.binary} at {hub.addr}; redis-server {redis_ver} on port {redis_port}")
        import redis as redis_mod

        # redis-py at its fastest reads replies with hiredis's C parser (make bench installs redis[hiredis]); without
        # it the pure-Python parser is used, and the report says which.
        parser = "hiredis" if getattr(redis_mod.connection, "HIREDIS_AVAILABLE", False) else "pure Python"
        systems = ["flow", "redis"]
        print(f"redis-py {redis_mod.__version__} ({parser} parser); window {WINDOW}, flow queue {FLOW_QUEUE}, "
              f"{args.rounds} rounds x {args.duration} s (+{args.warmup} s warm-up)")

        for i in range(args.rounds):
            for row in rows:
                # The systems in turn within each round, so a drift in the machine's speed touches both alike.
                order = systems if i % 2 == 0 else systems[::-1]
                for system in order:
                    channel = f"bench.{row.name}.{system}.{i}"
                    r = run_pair(system, hub, redis_port, payloads[row.name], channel, args.warmup, args.duration)
                    if r["size"] != row.size:
                        raise RuntimeError(f"{system} delivered {r['size']} bytes, not {row.size}")
                    row.rounds[system].append(r)
                    print(f"  round {i + 1} {row.name:4} {system:14}: {rate(r):8.0f} msg/s  {us_per_msg(r):6.1f} us "
                          f"cpu/msg  (gap {r['gap']}, dropped {r['dropped']})", flush=True)

        print(f"shm: 1 MB frames to a Python subscriber over the Unix socket (shared memory) vs TCP, window "
              f"{SHM_WINDOW}", flush=True)
        shm = run_shm(hub, args.rounds, args.warmup, args.duration)
        print(f"sketch: 100 Hz fast tick for {args.jitter_seconds} s, with a 50 Hz PCM subscription", flush=True)
        sk = run_sketch(hub, pcm, args.jitter_seconds)
        print("sigint: Ctrl-C into a satellite blocked in recv and in call, 10 times each", flush=True)
        sigint = run_sigint(hub, 10)
    except KeyboardInterrupt:
        print("bench_python: interrupted", file=sys.stderr)
        return 130
    finally:
        stop(hub_proc)
        stop(redis_proc)
        shutil.rmtree(work, ignore_errors=True)

    summary, table = [], []
    for row in rows:
        f, r = row.median("flow"), row.median("redis")
        ratio = rate(f) / rate(r)
        drops = sum(x["gap"] + x["dropped"] for x in row.rounds["flow"])
        summary.append(
            f"SUMMARY python-sub {row.name} flow={rate(f):.0f} msg/s redis-py={rate(r):.0f} msg/s ratio={ratio:.2f} "
            f"(target >= {row.target}) cpu/msg flow={us_per_msg(f):.1f} us redis-py={us_per_msg(r):.1f} us "
            f"flow drops={drops}"
        )
        table.append((row, f, r, ratio, drops))
    shm_line, _, shm_ratio = shm_summary(shm)
    summary.append(shm_line)
    late_ms = [x * 1e3 for x in sk["late_s"]]
    rf = sk["rust"]["fast"]
    p99 = pct(late_ms, 0.99)
    summary.append(
        f"SUMMARY python-sketch fast_tick 100Hz late p50={pct(late_ms, 0.5):.3f} ms p99={p99:.3f} ms "
        f"max={max(late_ms):.3f} ms missed={sk['missed']} (target p99 <= 2.0 ms) "
        f"Events.jitter p50={rf['p50_us'] / 1e3:.3f} ms p99={rf['p99_us'] / 1e3:.3f} ms max={rf['max_us'] / 1e3:.3f} ms ticks={rf['ticks']}"
    )
    sig_all = sigint["recv"] + sigint["call"]
    summary.append(
        f"SUMMARY python-sigint KeyboardInterrupt after SIGINT recv p50={pct(sigint['recv'], 0.5):.1f} ms "
        f"max={max(sigint['recv']):.1f} ms call p50={pct(sigint['call'], 0.5):.1f} ms max={max(sigint['call']):.1f} ms "
        f"(target <= 100 ms)"
    )
    for line in summary:
        print(line)
    targets = [(f"python-sub {row.name} >= {row.target}x redis-py", ratio >= row.target) for row, _, _, ratio, _ in
               table] + [(f"python-shm 1MB >= {SHM_TARGET}x TCP", shm_ratio >= SHM_TARGET),
                         ("python-sketch fast_tick p99 <= 2 ms", p99 <= 2.0),
                         ("python-sigint every Ctrl-C within 100 ms", max(sig_all) <= 100.0)]
    for name, ok in targets:
        print(f"TARGET {name}: {'met' if ok else 'MISSED'}")

    if args.write:
        write_doc(args, table, shm, sk, late_ms, summary, targets, hub, redis_ver, parser, jpeg_src, pcm_src)
        print(f"wrote {args.write}")
    return 0


def write_doc(args, table, shm, sk, late_ms, summary, targets, hub, redis_ver, parser, jpeg_src, pcm_src) -> None:
    import redis as redis_mod

    rf = sk["rust"]["fast"]
    cpu = platform.processor() or platform.machine()
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                cpu = line.split(":", 1)[1].strip()
                break
    except OSError:
        pass
    lines = [
        "# Python SDK benchmark (`bench_python.py`)",
        "",
        "`bench/python/bench_python.py` (run by `make bench`) measures the Python SDK (`flow`, the PyO3",
        "binding of the Rust `flow` crate) against redis-py pub/sub, side by side in the same run, and the timing of",
        "a Python `flow.Sketch`. Written by the run of "
        + time.strftime("%Y-%m-%d %H:%M", time.localtime())
        + f" (load average {args.load:.2f} when it started: the machine is shared, and other work may have run "
        "meanwhile).",
        "",
        f"Machine: {os.cpu_count()} cores ({cpu}), Python {platform.python_version()}, "
        f"`flow-hub` {'release' if 'release' in str(hub.binary) else 'debug'} build, redis-server {redis_ver}, "
        f"redis-py {redis_mod.__version__} ({parser} parser).",
        "",
        "## Python subscriber, messages/s and CPU per message",
        "",
        f"Median of {args.rounds} rounds of {args.duration:g} s (after {args.warmup:g} s of warm-up), the systems in "
        "turn; CPU is the subscriber process's own (`getrusage(RUSAGE_SELF)`, user + system, the SDK's tokio threads "
        "included) over the measured window, divided by the messages it received.",
        "",
        "| payload | flow msg/s | redis-py msg/s | ratio (target) | flow CPU/msg | redis-py CPU/msg | flow drops |",
        "|---|---:|---:|---:|---:|---:|---:|",
    ]
    for row, f, r, ratio, drops in table:
        label = f"{row.name} ({row.size} B)"
        lines.append(
            f"| {label} | {rate(f):.0f} | {rate(r):.0f} | {ratio:.2f}x (>= {row.target}x) | {us_per_msg(f):.1f} us "
            f"| {us_per_msg(r):.1f} us | {drops} |"
        )
    lines += [
        "",
        "Every round's rate, msg/s (flow / redis-py): "
        + "; ".join(
            row.name + " " + ", ".join(f"{rate(a):.0f}/{rate(b):.0f}" for a, b in zip(row.rounds["flow"],
                                                                                      row.rounds["redis"]))
            for row, *_ in table
        )
        + ". On this shared two-core VM the same code's rate drifts by up to a third between "
        "runs, for both systems alike; taking the systems in turn keeps the ratio fair under that drift.",
        "",
        "## Shared memory: 1 MB frames over the Unix socket against TCP",
        "",
        "A Python publisher and a Python subscriber, each a process of its own, both on the hub's Unix socket (the "
        "frame is copied once into the publisher's segment and reaches the subscriber by reference, read in place "
        "through `memoryview`) or both over TCP (copied through the publisher's socket, the hub and the "
        f"subscriber's socket); a window of {SHM_WINDOW} frames, since over TCP the hub's 8 MB per-subscriber "
        "lane would otherwise drop the oldest. Median of the rounds, the transports in turn; `by reference` is "
        "the share of the subscriber's messages whose `Message.in_shared_memory` was true.",
        "",
        "| transport | msg/s | CPU/msg (subscriber) | by reference | drops |",
        "|---|---:|---:|---:|---:|",
        *[
            f"| {name} | {rate(r):.0f} | {us_per_msg(r):.1f} us | {by_reference(r):.0%} | "
            f"{sum(x['gap'] + x['dropped'] for x in shm[key])} |"
            for key, name in (("unix", "Unix socket (shared memory)"), ("tcp", "TCP"))
            for r in [median_round(shm[key])]
        ],
        "",
        f"Ratio {rate(median_round(shm['unix'])) / rate(median_round(shm['tcp'])):.2f}x (target >= {SHM_TARGET}x). "
        "Every round, msg/s (Unix / TCP): "
        + ", ".join(f"{rate(a):.0f}/{rate(b):.0f}" for a, b in zip(shm["unix"], shm["tcp"])) + ".",
        "",
        "## Sketch at 100 Hz",
        "",
        f"A `flow.Sketch` subclass with `fast_ms = 10` for {args.jitter_seconds:g} s, subscribed to a 50 Hz PCM "
        f"channel fed by another process ({sk['messages']} messages handled meanwhile). Lateness of each `fast_tick` "
        "call against its ideal schedule, measured in Python with `time.monotonic()`; `Events.jitter()` is the "
        "Rust side's own view (lateness when the wait ends, before Python is called; its percentiles are log2 "
        "bucket bounds, so 2.047 ms means between 1.024 and 2.047 ms). tokio's timer counts whole milliseconds (a "
        "deadline fires on the millisecond tick after it), so the pulses are not tokio intervals: the runtime's timer "
        "wakes the waiting Python thread 2 ms early and the thread sleeps the rest itself (`events.rs`); with tokio "
        "intervals the same run measured p50 1.28 ms and p99 1.65 ms.",
        "",
        "| measure | p50 | p99 (target <= 2 ms) | max | ticks | missed slots |",
        "|---|---:|---:|---:|---:|---:|",
        f"| Python, `fast_tick` call | {pct(late_ms, 0.5):.3f} ms | {pct(late_ms, 0.99):.3f} ms | {max(late_ms):.3f} ms "
        f"| {len(late_ms)} | {sk['missed']} |",
        f"| `Events.jitter()['fast']` | {rf['p50_us'] / 1e3:.3f} ms | {rf['p99_us'] / 1e3:.3f} ms | "
        f"{rf['max_us'] / 1e3:.3f} ms | {rf['ticks']} | |",
        "",
        "## Method",
        "",
        f"- Payloads, from the shared fixtures: `{jpeg_src}` (a real 640x360 camera JPEG, as on `Agent.video`) and "
        f"20 ms of speech cut one second into `{pcm_src}` (s16 mono 22050 Hz, 882 bytes, as on `Agent.audio`), the "
        "same as hub-bench.",
        "- Servers started by the benchmark on free loopback ports: `flow-hub` (the hub alone, fresh data directory) "
        "and Debian's `redis-server` (`--save '' --appendonly no`); both are stopped at the end, also on Ctrl-C.",
        "- Publisher and subscriber are two separate Python processes for each system (multiprocessing, spawn), "
        "the publisher in Python on both sides: `flow.Publisher.publish` against redis-py `PUBLISH`, the same "
        "payload object each time. redis-py publishes in pipelined batches of up to "
        f"{REDIS_BATCH} (one round trip per batch), because a plain `publish()` waits for the server's reply and "
        "would make Redis's figure its publisher's round trips; `flow`'s publish is already asynchronous.",
        f"- Flat out within a window: the publisher never runs more than {WINDOW} messages ahead of what the "
        "subscriber has received (a counter in shared memory, the same for both systems), as hub-bench's window "
        "mode. This is the subscriber's sustainable rate with nothing lost, and it keeps the two systems' "
        "different overload behaviours out of the figure: the hub drops the oldest messages of a slow "
        "subscriber's lane (64 messages by default) and the SDK's local queue does the same "
        f"(`Client.connect(queue={FLOW_QUEUE})`), counted here through `Message.gap` and `Subscription.dropped` "
        "(the `flow drops` column: 0 means every message arrived), while Redis buffers for a slow subscriber in "
        "the server until its output-buffer limit and then disconnects it. Flat out without a window, `flow` "
        "would report what the subscriber managed while the rest was dropped, and Redis would grow its buffer "
        "and cut the subscriber off.",
        f"- redis-py runs with the {parser} parser (`redis[hiredis]`, its fastest) and RESP2 (`protocol=2`): "
        "redis-py 8 defaults to RESP3, where each pub/sub message is a push reply that redis-py first formats into a "
        "debug log string even with logging off (`handle_pubsub_push_response` in `redis/_parsers/hiredis.py`), "
        "about 0.5 ms per JPEG; RESP2, redis-py's protocol before 8, avoids that bug.",
        "- The subscriber reads `for msg in sub` (flow) and `pubsub.listen()` (redis-py), and takes a "
        "`memoryview` of each payload (zero-copy on `flow`, `bytes` on redis-py).",
        "- Both cores are shared by the publisher, the server and the subscriber, so the rates are the whole "
        "pipeline's on this machine; the CPU per message is the subscriber's alone.",
        "",
        "## Run",
        "",
        "```",
        *summary,
        *[f"TARGET {name}: {'met' if ok else 'MISSED'}" for name, ok in targets],
        "```",
        "",
    ]
    args.write.parent.mkdir(parents=True, exist_ok=True)
    args.write.write_text("\n".join(lines))


if __name__ == "__main__":
    sys.exit(main())
