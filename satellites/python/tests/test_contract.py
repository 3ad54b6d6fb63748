"""The agent's contract in Python: the channel names and kinds are the Rust contract's (as a running agent's own
channels show), every JSON test vector the page is held to parses through the typed helpers with every field kept, and a
message the contract refuses is a clear ValueError."""

import json

import pytest

from conftest import REPO, fits
from flow import _native, agent

VECTORS = REPO / "crates" / "contract" / "vectors"


def vector(name):
    return json.loads((VECTORS / f"{name}.json").read_text())


def test_the_module_channels_of_a_running_agent_are_contract_channels_of_the_same_kind(client):
    running = {c["name"]: c["kind"] for c in client.channels()}
    ours = {n: k for n, k in running.items() if n.startswith(agent.SAY.split(".")[0] + ".")}
    assert agent.SAY in ours and agent.AVATAR in ours and agent.SPEECH in ours, ours
    for name, kind in ours.items():
        if name.startswith((agent.ASR_CLAIM_PREFIX, agent.ASR_PRESENCE_PREFIX)):
            continue
        assert name in agent.CHANNELS, f"{name} is not in the contract"
        assert agent.CHANNELS[name][0] == kind, name
    assert json.loads(agent.HEADERS[agent.AUDIO])["rate"] == 22050


def test_every_detections_vector_parses_and_round_trips(client):
    v = vector("detections")
    assert v["channel"] == agent.DETECTIONS
    for message in v["messages"]:
        d = agent.Detections.from_msg(message)
        assert fits(message, d.to_dict()), (d.to_dict(), message)
        assert d.frame.width > 0
        for face in d.faces or []:
            assert face.w > 0 and face.h > 0
        for code in d.codes or []:
            assert code.kind and len(code.polygon) >= 3
    gaze = agent.Gaze.from_msg(v["gaze_command"])
    assert gaze.cmd == "gaze" and 0 <= gaze.x <= 1


def test_every_avatar_command_and_rule_change_vector_parses_and_round_trips():
    v = vector("avatar")
    assert v["channel"] == agent.AVATAR
    for command in v["commands"]:
        assert fits(command, agent.Avatar.from_msg(command).to_dict())
    r = vector("rules")
    assert r["channel"] == agent.RULES
    for change in r["messages"]:
        parsed = agent.RuleChange.from_msg(change)
        assert fits(change, parsed.to_dict()) and parsed.rule


def test_a_message_that_does_not_fit_the_contract_is_a_value_error_with_the_reason():
    with pytest.raises(ValueError, match="not a valid detections message: .*frame"):
        agent.Detections.from_msg({"faces": []})
    with pytest.raises(ValueError, match="no contract type"):
        _native.contract_check("nonsense", b"{}")


def test_records_are_read_only_and_name_missing_fields():
    h = agent.Heard.from_msg({"text": "hello", "final": True})
    assert h.text == "hello"
    with pytest.raises(AttributeError, match="no field 'colour'"):
        h.colour
    with pytest.raises(AttributeError, match="read-only"):
        h.text = "changed"
