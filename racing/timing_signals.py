"""What a timing device (or the timekeeper page's keys) sends, read into a ``Signal`` for
``racing.timing``: our JSON (``{"signal": "crossing", "at_ms": ...}``, docs/league.md "The
timing device protocol"), or the DeepRacer Event Manager's lap timer's events as it sends them.
"""

from __future__ import annotations

from dataclasses import dataclass

SIGNALS = ("crossing", "off_track", "reset", "undo", "finish")
MAX_CLOCK_MS = 2**53  # a clock's reading [ms]: what JSON and a browser's numbers hold exactly


class SignalUnreadable(ValueError):
    """A signal's body that cannot be read (the device endpoint's 400); the message says why."""


@dataclass(frozen=True)
class Signal:
    kind: str
    at_ms: int | None = None  # the clock's reading, for a crossing


SIGNAL_FORMAT = (  # what a device sends, in words, for any body that is not a signal
    'Send JSON: {"signal": "crossing", "at_ms": <whole milliseconds>}, or a signal of '
    "off_track, reset, undo or finish."
)


# The DeepRacer Event Manager's lap timer (a Raspberry Pi's light gates) sends each crossing as
# {"event": "lap", "timestamp": <ms since the epoch, the Pi's clock>, "gpio", "lapNumber",
# "sensorLapCount"}, and {"event": "connected", "timestamp", "serverInfo"} once to each client
# that connects (aws-solutions-library-samples/guidance-for-aws-deepracer-event-management
# 18030a1, leaderboard-timer/timer.js:99-105, 232-241); DREM's timekeeper page ignores every event
# but "lap" (website/src/pages/timekeeper/pages/racePage.tsx:241-285). A lap is a crossing at its
# timestamp; "connected" a greeting (``HELLO``), answered with the state and changing nothing.
DREM_EVENTS = {"lap": "crossing", "connected": "hello"}
HELLO = "hello"


def signal_read(data: object) -> Signal:
    """The signal in a device's (or the page's) JSON body, ours or DREM's lap timer's
    (``DREM_EVENTS``); ``SignalUnreadable`` says what is wrong with it: not an object, an
    unknown signal, a crossing without its clock reading."""
    if isinstance(data, dict) and "signal" not in data and isinstance(data.get("event"), str):
        if data["event"] not in DREM_EVENTS:
            raise SignalUnreadable(
                f"Unknown lap timer event {data['event']!r}: DREM's timer sends lap and connected."
            )
        if data["event"] == "connected":
            return Signal(HELLO)
        data = {"signal": "crossing", "at_ms": data.get("timestamp")}
    if not isinstance(data, dict) or not isinstance(data.get("signal"), str):
        raise SignalUnreadable(SIGNAL_FORMAT)
    kind, at_ms = data["signal"], data.get("at_ms")
    if kind not in SIGNALS:
        raise SignalUnreadable(f"Unknown signal {kind!r}: send one of {', '.join(SIGNALS)}.")
    if kind == "crossing" and (type(at_ms) is not int or not 0 <= at_ms < MAX_CLOCK_MS):
        raise SignalUnreadable(
            "A crossing needs the clock's reading, at_ms: whole milliseconds from 0 to 2^53."
        )
    return Signal(kind, at_ms if kind == "crossing" else None)
