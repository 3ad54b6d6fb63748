"""Python satellites for the robot-agent flow hub.

A binding of the Rust ``flow`` SDK (``flow._native``): the same protocol code as every Rust satellite, with the
GIL released while waiting, so Ctrl-C stops a blocked ``recv`` or ``call``.

    from flow import Client, agent

    with Client.connect() as client:          # tcp://127.0.0.1:9000, token from data/token
        for msg in client.subscribe(agent.TRANSCRIPT):
            print(msg.json())

See ``Sketch`` for the PySketch style (setup + tick handlers) and ``flow.agent`` for the agent's channels.
"""

from ._native import (
    AuthError,
    ChannelError,
    Client,
    ConnectionLost,
    DatabaseError,
    Database,
    Events,
    FlowError,
    Loan,
    Message,
    Overloaded,
    Publisher,
    Service,
    ServiceFailed,
    ServiceGone,
    Subscription,
    TimeoutError,
    __version__,
)
from .sketch import Sketch
from . import agent

__all__ = [
    "AuthError",
    "ChannelError",
    "Client",
    "ConnectionLost",
    "Database",
    "DatabaseError",
    "Events",
    "FlowError",
    "Loan",
    "Message",
    "Overloaded",
    "Publisher",
    "Service",
    "ServiceFailed",
    "ServiceGone",
    "Sketch",
    "Subscription",
    "TimeoutError",
    "agent",
    "__version__",
]
