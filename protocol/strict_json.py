"""Strict JSON for control messages: what a request's or reply's JSON may hold, and the
outermost members of a frame refused only for breaking a limit.

A frame is read by Python's parser with hooks that refuse what JSON has no room for or a
reader could misuse: non-finite numbers (`1e400` is not read as infinity, `NaN` and
`Infinity` are not JSON), integers of more than MAX_INTEGER_DIGITS digits, arrays and
objects nested more than MAX_NESTING deep. Each is refused by name (`JSONRefused`).

A frame refused for a limit is still JSON: `outer_members()` reads its outermost object
with every nested value taken as null and every refused number as REFUSED, so the reply
can carry the request's `id`. It first checks the whole frame's syntax with a linear scan
that keeps its own stack (no recursion, so no nesting depth can exhaust Python's), and it
runs only for frames already refused, so requests that keep the limits never pay for it.
"""

from __future__ import annotations

import json
import math
import re

MAX_NESTING = 16  # arrays/objects inside each other (a `set` needs 4)
MAX_INTEGER_DIGITS = 18  # any int64 of 18 digits; a longer integer is refused
REFUSED = object()  # a number outer_members() read but a request may not hold


class JSONRefused(ValueError):
    """The one-line reason a frame is refused; `limit` when it is JSON that breaks a limit
    (a number or the nesting), not text that is no JSON at all."""

    def __init__(self, message: str, limit: bool = False) -> None:
        super().__init__(message)
        self.limit = limit


def _finite_float(text: str) -> float:
    value = float(text)
    if not math.isfinite(value):
        raise JSONRefused(
            f"number {text[:24]} is not finite (larger than a double holds)", limit=True
        )
    return value


def _bounded_int(text: str) -> int:
    digits = len(text.lstrip("-"))
    if digits > MAX_INTEGER_DIGITS:
        raise JSONRefused(
            f"integer of {digits} digits is out of range (at most {MAX_INTEGER_DIGITS} digits)",
            limit=True,
        )
    return int(text)


def _not_json(name: str):
    raise ValueError(f"{name} is not a JSON number")


def _depth(obj) -> int:
    """How deeply arrays and objects nest in a parsed JSON value (iterative: no recursion)."""
    deepest, stack = 0, [(obj, 1)]
    while stack:
        value, depth = stack.pop()
        if isinstance(value, (dict, list)):
            deepest = max(deepest, depth)
            if depth <= MAX_NESTING:
                stack.extend(
                    (child, depth + 1)
                    for child in (value.values() if isinstance(value, dict) else value)
                )
    return deepest


def read_object(frame: bytes, what: str) -> dict:
    """A frame's JSON object within the limits; JSONRefused says what is wrong."""
    try:
        obj = json.loads(
            frame.decode("utf-8"),
            parse_constant=_not_json,
            parse_float=_finite_float,
            parse_int=_bounded_int,
        )
    except UnicodeDecodeError:
        raise JSONRefused(f"{what} is not UTF-8 text") from None
    except JSONRefused as exc:
        raise JSONRefused(f"{what}: {exc}", limit=True) from None
    except RecursionError:
        raise JSONRefused(
            f"{what} nests arrays/objects deeper than {MAX_NESTING} levels", limit=True
        ) from None
    except ValueError as exc:
        raise JSONRefused(f"{what} is not valid JSON ({str(exc).splitlines()[0]})") from None
    if not isinstance(obj, dict):
        raise JSONRefused(f"{what} must be a JSON object, not {type(obj).__name__}")
    if _depth(obj) > MAX_NESTING:
        raise JSONRefused(
            f"{what} nests arrays/objects deeper than {MAX_NESTING} levels", limit=True
        )
    return obj


# JSON's tokens (RFC 8259): a string without raw control characters, a number, a literal, a
# structural character; whitespace is space, tab, LF and CR.
_TOKEN = re.compile(
    r'(?P<string>"[^"\\\x00-\x1f]*(?:\\(?:["\\/bfnrt]|u[0-9a-fA-F]{4})[^"\\\x00-\x1f]*)*")'
    r"|(?P<value>-?(?:0|[1-9][0-9]*)(?:\.[0-9]+)?(?:[eE][+-]?[0-9]+)?|true|false|null)"
    r"|(?P<open>[\[{])|(?P<close>[\]}])|(?P<comma>,)|(?P<colon>:)"
)
_SPACE = re.compile(r"[ \t\n\r]*")
_CLOSE = {"[": "]", "{": "}"}


def _nested_spans(text: str) -> list[tuple[int, int]] | None:
    """Where the values nested in the outermost object lie, as (start, end) of each array or
    object one level in, when `text` is one JSON object; None when it is not."""
    stack: list[str] = []
    spans: list[tuple[int, int]] = []
    start = 0
    expect = "value"  # value, value or close, key, key or close, colon, after a value
    pos = _SPACE.match(text).end()
    while pos < len(text):
        m = _TOKEN.match(text, pos)
        if m is None:
            return None
        kind, token = m.lastgroup, m.group()
        if not stack and (kind != "open" or token != "{" or expect != "value"):
            return None  # one object, and nothing after it
        if expect in ("value", "value/close") and kind in ("string", "value"):
            expect = "after"
        elif expect in ("value", "value/close") and kind == "open":
            stack.append(token)
            if len(stack) == 2:
                start = pos
            expect = "value/close" if token == "[" else "key/close"
        elif expect in ("key", "key/close") and kind == "string":
            expect = "colon"
        elif expect == "colon" and kind == "colon":
            expect = "value"
        elif expect == "after" and stack and kind == "comma":
            expect = "value" if stack[-1] == "[" else "key"
        elif (
            expect in ("after", "value/close", "key/close")
            and stack
            and kind == "close"
            and token == _CLOSE[stack[-1]]
        ):
            if len(stack) == 2:
                spans.append((start, m.end()))
            stack.pop()
            expect = "after"
        else:
            return None
        pos = _SPACE.match(text, m.end()).end()
    return spans if expect == "after" and not stack else None


def _lenient_float(text: str):
    value = float(text)
    return value if math.isfinite(value) else REFUSED


def _lenient_int(text: str):
    return REFUSED if len(text.lstrip("-")) > MAX_INTEGER_DIGITS else int(text)


def outer_members(frame: bytes) -> dict | None:
    """The outermost object's members of a UTF-8 frame that is one JSON object, however deep
    it nests and whatever numbers it holds: nested arrays and objects read as None, numbers
    out of range as REFUSED. None when the frame is not one JSON object."""
    try:
        text = frame.decode("utf-8")
    except UnicodeDecodeError:
        return None
    spans = _nested_spans(text)
    if spans is None:
        return None
    pieces, end = [], 0
    for a, b in spans:
        pieces += [text[end:a], "null"]
        end = b
    flat = "".join(pieces) + text[end:]
    return json.loads(flat, parse_float=_lenient_float, parse_int=_lenient_int)
