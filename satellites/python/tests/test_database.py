"""The pair database from Python: values of any JSON type, deletion, listing, separate databases, and the same
values seen by flowctl."""

import json

import pytest

from flow import DatabaseError


def test_values_round_trip_and_are_what_rust_reads(agent, client):
    db = client.db
    db.set("robot.name", "Armanda")
    db.set("robot.pose", {"x": 1.5, "y": -2, "tags": ["home", None, True]})
    assert db.get("robot.name") == "Armanda"
    assert db.get("robot.pose") == {"x": 1.5, "y": -2, "tags": ["home", None, True]}
    assert db.get("robot.missing") is None
    assert db.get("robot.missing", 7) == 7
    assert {"robot.name", "robot.pose"} <= set(db.keys())
    out = agent.flowctl_run("db", "get", "robot.pose")
    assert json.loads(out) == {"x": 1.5, "y": -2, "tags": ["home", None, True]}
    db.delete("robot.name")
    assert db.get("robot.name") is None


def test_databases_are_separate_and_selecting_a_missing_one_fails(client):
    db = client.db
    db.set("shared", 1)
    db.create("lab")
    assert "lab" in db.databases()
    db.select("lab")
    assert db.get("shared") is None
    db.set("shared", 2)
    db.select("main")
    assert db.get("shared") == 1
    with pytest.raises(DatabaseError):
        db.select("nowhere")
