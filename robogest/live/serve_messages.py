"""The messages of ``robogest serve``'s protocol (module docstring of :mod:`robogest.live.server`): a text frame read
as a JSON object, its fields checked with an error that names the field, and the events sent back."""

from __future__ import annotations

import json

from robogest.errors import InputError

PROTOCOL_VERSION = 1


def parse_message(msg: str) -> dict:
    """A text frame as a JSON object with a string ``type``; InputError naming what is wrong, whatever the input
    (Python's decoder raises RecursionError on deep nesting and ValueError on integers of over 4300 digits)."""
    try:
        obj = json.loads(msg)
    except json.JSONDecodeError as e:
        raise InputError(f"not JSON ({e.msg} at character {e.pos}); send one JSON object per text frame") from None
    except RecursionError:
        raise InputError("JSON nested too deeply to decode; send one flat JSON object per text frame") from None
    except ValueError as e:  # "Exceeds the limit (4300 digits) for integer string conversion"
        why = str(e).split(";")[0]
        raise InputError(f"JSON with a number too long to decode ({why}); send plain numbers") from None
    if not isinstance(obj, dict) or not isinstance(obj.get("type"), str):
        raise InputError('a message must be a JSON object with a string "type"')
    return obj


def check_id(obj: dict) -> None:
    """The ``id`` echoed back: a string, an integer that fits 64 bits, or absent."""
    i = obj.get("id")
    if i is None or (isinstance(i, str) and len(i) <= 256) or (type(i) is int and abs(i) < 2**63):
        return
    raise InputError('"id" must be a string of at most 256 characters or an integer of 64 bits')


def message_body(obj: dict, what: str) -> dict:
    """The message's per-utterance body language (``style``, ``amount``, ``gestures``), checked: InputError naming
    the field."""
    from robogest.live.style import body_language

    body = {k: obj[k] for k in ("style", "amount", "gestures") if obj.get(k) is not None}
    body_language(**body, what=what)
    return body


def plain_event(e: dict) -> dict:
    return {k: (float(v) if hasattr(v, "__float__") and not isinstance(v, bool | int) else v) for k, v in e.items()
            if k != "type"}  # fmt: skip
