"""The robot agent's channels and messages, from the Rust contract crate (``agent-contract``).

Channel names come from the contract, never from strings typed here:

    from flow import agent
    sub = client.subscribe(agent.DETECTIONS)
    for msg in sub:
        d = agent.Detections.from_msg(msg)
        for face in d.faces or []:
            print(face.x, face.y, face.w, face.h)

Each message type is checked by its Rust definition (serde) before Python sees it, so a Python consumer accepts
what a Rust consumer accepts, and the fields are the Rust fields.
"""

from __future__ import annotations

import json
from typing import Any, Iterator, Union

from . import _native

_contract = _native.contract_channels()

#: Every fixed channel of the agent: ``{name: (kind, doc)}`` with kind "stream" or "service".
CHANNELS: dict[str, tuple[str, str]] = dict(_contract["channels"])
#: The headers of the channels whose producer is fixed (JSON text).
HEADERS: dict[str, str] = dict(_contract["headers"])
#: Prefix of whisper satellites' per-utterance claim channels.
ASR_CLAIM_PREFIX: str = _contract["asr_claim_prefix"]
#: Prefix of whisper satellites' presence channels.
ASR_PRESENCE_PREFIX: str = _contract["asr_presence_prefix"]


def _name(suffix: str) -> str:
    # Looked up rather than spelled here: a channel renamed in the contract fails at import, not at run time.
    for name in CHANNELS:
        if name.split(".", 1)[1] == suffix:
            return name
    raise ImportError(f"the contract has no channel ending in {suffix!r}")


AUDIO = _name("audio")
VIDEO = _name("video")
VIDEO_Y = _name("video.y")
AUDIO_FFT = _name("audio.fft")
CTRL = _name("ctrl")
AVATAR = _name("avatar")
SPEECH = _name("speech")
SAY = _name("say")
TRANSCRIPT = _name("transcript")
FACES = _name("faces")
MOTION = _name("motion")
CODES = _name("codes")
DETECTIONS = _name("detections")
RULES = _name("rules")
ASR_SUBMIT = _name("asr.submit")
CHAT = _name("chat")
CHAT_REPLY = _name("chat.reply")
TRANSCRIPT_PAUSE = _name("transcript.pause")


class Record:
    """A contract message with its fields as attributes (nested objects too); ``to_dict()`` gives the JSON back."""

    __slots__ = ("_fields",)

    def __init__(self, fields: dict[str, Any]) -> None:
        object.__setattr__(self, "_fields", fields)

    def __getattr__(self, name: str) -> Any:
        try:
            return _wrap(self._fields[name])
        except KeyError:
            raise AttributeError(f"{type(self).__name__} has no field {name!r}") from None

    def __setattr__(self, name: str, value: Any) -> None:
        raise AttributeError(f"{type(self).__name__} is read-only")

    def __getitem__(self, name: str) -> Any:
        return _wrap(self._fields[name])

    def __iter__(self) -> Iterator[str]:
        return iter(self._fields)

    def __eq__(self, other: object) -> bool:
        return isinstance(other, Record) and other._fields == self._fields

    def __repr__(self) -> str:
        inner = ", ".join(f"{k}={v!r}" for k, v in self._fields.items())
        return f"{type(self).__name__}({inner})"

    def to_dict(self) -> dict[str, Any]:
        return json.loads(json.dumps(self._fields))

    #: The contract type this class checks against (set on each subclass; underscored so no field can hide it).
    _kind = ""

    @classmethod
    def from_msg(cls, msg: Union["_native.Message", bytes, str, dict]):
        """Parses a message (or its payload) and checks it against the contract; ``ValueError`` if it does not fit."""
        if isinstance(msg, dict):
            data = json.dumps(msg).encode()
        elif isinstance(msg, str):
            data = msg.encode()
        elif isinstance(msg, _native.Message):
            data = msg.bytes()
        else:
            data = bytes(msg)
        return cls(json.loads(_native.contract_check(cls._kind, data)))


def _wrap(value: Any) -> Any:
    if isinstance(value, dict):
        return Record(value)
    if isinstance(value, list):
        return [_wrap(v) for v in value]
    return value


def _record(kind: str, doc: str) -> type:
    return type(kind.title().replace("_", ""), (Record,), {"_kind": kind, "__doc__": doc, "__slots__": ()})


Detections = _record("detections", "Everything the vision module saw in one frame (``Agent.detections``).")
Faces = _record("faces", "Face boxes of one frame (``Agent.faces``).")
Motion = _record("motion", "Motion of one frame (``Agent.motion``).")
Codes = _record("codes", "New appearances of QR and barcodes (``Agent.codes``).")
Gaze = _record("gaze", "A gaze command of the avatar (on ``Agent.avatar``).")
Transcript = _record("transcript", "A transcript from a whisper satellite (``Agent.transcript``).")
Vad = _record("vad", "A voice-activity event (``Agent.transcript``).")
Heard = _record("heard", "Anything on ``Agent.transcript``, read leniently: text, final flag, VAD kind.")
Avatar = _record("avatar", "An avatar command (``Agent.avatar``): blink, gaze, mood, visemes, speech_stop, say.")
SayRequest = _record("say_request", "What ``Agent.say`` takes.")
SayAnswer = _record("say_answer", "What ``Agent.say`` answers.")
Ctrl = _record("ctrl", "A control message from the page (``Agent.ctrl``).")
RuleChange = _record("rule_change", "One entry of the brain's rule trace (``Agent.rules``).")
