"""Type stubs of ``flow._native``, the PyO3 binding of the Rust ``flow`` SDK (see satellites/python/src)."""

from typing import Any, Awaitable, Callable, Iterator, AsyncIterator, Optional, Union

import numpy

Payload = Union[bytes, bytearray, memoryview, str, dict, list, "Message", Any]
"""What may be published or sent: bytes (shared, not copied), str (UTF-8), dict or list (JSON), a Message, or any
C-contiguous buffer such as a numpy array (sent as its bytes)."""

__version__: str

class FlowError(Exception):
    """Anything that went wrong talking to the hub."""

class AuthError(FlowError):
    """The hub refused the login token, or no token was found (the message names the file)."""

class TimeoutError(FlowError):
    """No answer in time: a service call past its timeout, or a wait that gave up."""

class ServiceGone(FlowError):
    """The service's owner left before it answered."""

class ServiceFailed(FlowError):
    """The service answered with an error; the message is the service's."""

class Overloaded(FlowError):
    """Too much in flight: the service's queue or a hub limit is full; try again later."""

class ChannelError(FlowError):
    """The channel does not exist, exists already, is of the other kind or belongs to someone else."""

class DatabaseError(FlowError):
    """The pair database refused: no such database, or a storage failure."""

class ConnectionLost(FlowError):
    """The connection is down (it reconnects by itself unless closed), or the client was closed."""

class Message:
    """One message. Supports the buffer protocol: ``memoryview(msg)`` reads the payload without a copy."""

    @property
    def channel(self) -> str: ...
    @property
    def seq(self) -> int:
        """Position on the channel, from 1 (0 for a service answer)."""
    @property
    def ts_us(self) -> int:
        """Hub clock when published, microseconds since the Unix epoch."""
    @property
    def gap(self) -> int:
        """Messages of this channel dropped just before this one (drop-oldest on a slow reader)."""
    @property
    def in_shared_memory(self) -> bool:
        """Whether the payload lies in a shared-memory segment this process maps (it came by reference over the
        hub's Unix socket): its views, numpy arrays included, read the segment itself."""
    @property
    def data(self) -> memoryview:
        """The payload as a read-only memoryview, without a copy."""
    def bytes(self) -> bytes:
        """The payload copied into bytes."""
    def text(self) -> str:
        """The payload as UTF-8 text (ValueError naming the channel if it is not)."""
    def json(self) -> Any:
        """The payload parsed as JSON (ValueError naming the channel if it is not)."""
    def pcm(self) -> numpy.ndarray:
        """The payload as a numpy int16 array (s16le), a view without a copy."""
    def __len__(self) -> int: ...

class Publisher:
    """A streaming channel this client owns; ``close()`` removes it."""

    @property
    def name(self) -> str: ...
    @property
    def has_subscribers(self) -> bool: ...
    @property
    def skipped(self) -> int:
        """Messages try_publish dropped because the connection was saturated."""
    def publish(self, payload: Payload) -> None:
        """Publishes one message; waits (GIL released) only while the send queue is full."""
    def try_publish(self, payload: Payload) -> bool:
        """Publishes unless the send queue is full; returns whether it was queued."""
    def loan(self, size: int) -> Optional["Loan"]:
        """A shared-memory slot of ``size`` bytes to write a message into in place (zero copy); None without shared
        memory (TCP, the hub's off), before the channel's segment has come, or while every slot is held."""
    def wait_subscribers(self, timeout: Optional[float] = None) -> bool:
        """Waits until someone subscribes; False if ``timeout`` seconds pass first."""
    def set_header(self, header: Union[dict, str]) -> None: ...
    def close(self) -> None: ...
    def __enter__(self) -> "Publisher": ...
    def __exit__(self, *exc: Any) -> bool: ...

class Loan:
    """A message written in place into a shared-memory slot: a writable buffer (``memoryview(loan)``,
    ``numpy.frombuffer(loan, dtype=...)``). Release every view before ``publish()`` or ``discard()``."""

    @property
    def channel(self) -> str: ...
    @property
    def pending(self) -> bool:
        """Neither published nor discarded yet."""
    def __len__(self) -> int: ...
    def publish(self, length: Optional[int] = None) -> None:
        """Publishes the message (its first ``length`` bytes); BufferError while a view of it is alive."""
    def discard(self) -> None:
        """Gives the slot back unpublished."""

class Subscription:
    """Messages of one channel in order; sticky by name across removals and reconnects."""

    @property
    def name(self) -> str: ...
    @property
    def dropped(self) -> int:
        """Messages dropped locally because the reader fell behind (drop-oldest)."""
    @property
    def header(self) -> Optional[str]:
        """The channel's header (JSON text) as of the last (re)subscription."""
    def recv(self, timeout: Optional[float] = None) -> Message:
        """The next message; TimeoutError after ``timeout`` seconds, ConnectionLost once the client is closed."""
    def recv_latest(self, timeout: Optional[float] = None) -> Message:
        """The newest message, skipping older queued ones."""
    def try_recv(self) -> Optional[Message]: ...
    def recv_async(self) -> Awaitable[Message]: ...
    def __iter__(self) -> Iterator[Message]: ...
    def __next__(self) -> Message: ...
    def __aiter__(self) -> AsyncIterator[Message]: ...
    def __anext__(self) -> Awaitable[Message]: ...

class Service:
    """A service this client offers; it answers until ``close()`` or the client closes."""

    @property
    def name(self) -> str: ...
    def close(self) -> None: ...
    def __enter__(self) -> "Service": ...
    def __exit__(self, *exc: Any) -> bool: ...

class Database:
    """The hub's pair database: JSON values by key in the selected database (``main`` by default)."""

    def get(self, key: str, default: Any = None) -> Any: ...
    def set(self, key: str, value: Any) -> None:
        """Stores a JSON-serialisable value; returns once the hub made it durable."""
    def delete(self, key: str) -> None: ...
    def keys(self) -> list[str]: ...
    def select(self, name: str) -> None:
        """Makes ``name`` this connection's database (DatabaseError if it does not exist)."""
    def create(self, name: str) -> None: ...
    def remove(self, name: str) -> None: ...
    def databases(self) -> list[str]: ...

class Client:
    """A connection to a flow hub; reconnects by itself, restoring channels and subscriptions."""

    @staticmethod
    def connect(
        addr: Optional[str] = None,
        token: Optional[str] = None,
        data_dir: Optional[str] = None,
        name: Optional[str] = None,
        *,
        queue: int = 64,
        reconnect: bool = True,
        timeout: float = 10.0,
    ) -> "Client":
        """Connects and logs in. ``addr`` defaults to $FLOW_ADDR, then tcp://127.0.0.1:9000; ``token`` to
        $FLOW_TOKEN, then ``data_dir``/token (``data_dir`` defaults to $ROBOT_AGENT_DATA, then ``data``).
        ``queue`` is each subscription's drop-oldest capacity; ``timeout`` bounds ordinary requests."""
    @property
    def name(self) -> str: ...
    @property
    def connected(self) -> bool: ...
    @property
    def db(self) -> Database: ...
    def publisher(
        self,
        name: str,
        header: Union[dict, str, None] = None,
        on_subscribers: Optional[Callable[[bool], None]] = None,
    ) -> Publisher:
        """Creates a streaming channel; ``on_subscribers(True)`` when the first subscriber arrives, ``(False)`` when
        the last leaves (on a background thread)."""
    def subscribe(self, name: str) -> Subscription: ...
    def serve(
        self,
        name: str,
        handler: Callable[[Message], Union[Payload, None, Awaitable[Union[Payload, None]]]],
        header: Union[dict, str, None] = None,
    ) -> Service:
        """Offers a service; the handler's exception reaches the caller as ServiceFailed."""
    def call(self, name: str, request: Payload, timeout: float = 5.0) -> Message:
        """Calls a service: TimeoutError, ServiceGone, ServiceFailed or ChannelError when it does not answer."""
    def call_async(self, name: str, request: Payload, timeout: float = 5.0) -> Awaitable[Message]: ...
    def channels(self) -> list[dict[str, Any]]:
        """Every channel: id, name, kind, owner, header, subscribers, messages, messages_per_s, bytes, dropped."""
    def ping(self) -> None: ...
    def close(self) -> None: ...
    def __enter__(self) -> "Client": ...
    def __exit__(self, *exc: Any) -> bool: ...

class Events:
    """The pulses and messages that drive a Sketch, merged in Rust."""

    def __init__(
        self,
        subscriptions: list[Subscription],
        fast_ms: Optional[float] = 10.0,
        slow_ms: Optional[float] = 100.0,
        one_sec: bool = True,
    ) -> None: ...
    def next(self) -> tuple[str, Optional[Message]]:
        """("fast" | "slow" | "one_sec", None) or ("message", msg); GIL released, Ctrl-C honoured."""
    def jitter(self) -> dict[str, dict[str, float]]:
        """Lateness per pulse: ticks, mean_us, p50_us, p99_us, max_us."""

def contract_channels() -> dict[str, Any]: ...
def contract_check(kind: str, data: bytes) -> str:
    """``data`` checked against the contract type ``kind``, as the Rust side writes it (JSON text)."""
