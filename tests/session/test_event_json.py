"""Event payloads decode as json.loads decodes them, whatever the bytes: the fast path for plain UTF-8
objects and json.loads for the rest give the same objects and the same errors."""

from __future__ import annotations

import json

import pytest

from teleprev.messages import Event
from teleprev.session.codec import _json_loads, decoder_for, encode

TICK = b'{"seq":241,"late_ms":0.045129,"flags":[],"active":true,"stamp_ns":1795809907139503529}'
CASES = [
    TICK,
    b'{"a":{"b":[1,2.5,"\\u00fc",null,false]},"big":123456789012345678901234567890}',
    '{"name":"grüße ✋"}'.encode(),
    b'{"x":NaN,"y":-Infinity}',
    b"{}",
    b'{"a":1} ',  # whitespace after: json.loads takes it
    b' {"a":1}',
    b'{"a":1}{"b":2}',  # two objects: an error
    b'{"a":1',
    b"{'a':1}",
    b'["not", "an", "object"]',
    b"",
    b"\xef\xbb\xbf" + TICK,  # a UTF-8 byte order mark
    TICK.decode().encode("utf-16"),
    TICK.decode().encode("utf-16-le"),
    TICK.decode().encode("utf-32-be"),
    b'{"s":"\xed\xa0\x80"}',  # a lone surrogate in UTF-8 bytes: json.loads reads it (surrogatepass)
    b'{"s":"\xff"}',
    b'{"a":1}\n',
]


def _outcome(fn, data):
    try:
        return "ok", repr(fn(data))
    except (ValueError, RecursionError) as exc:
        return type(exc).__name__, str(exc)


@pytest.mark.parametrize("data", CASES, ids=range(len(CASES)))
def test_event_json_decodes_as_json_loads(data):
    assert _outcome(_json_loads, data) == _outcome(json.loads, data)


def test_an_event_round_trips_through_its_decoder():
    decoder = decoder_for("teleprev.CommandTick", "jsonschema", b'{"title": "teleprev.CommandTick"}', "json")
    event = Event(1795809907139503529, "teleprev.CommandTick", {"seq": 241, "late_ms": 0.045129, "flags": ["x"]})
    assert decoder(encode(event)) == event
