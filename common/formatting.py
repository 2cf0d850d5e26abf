"""Times and durations as the console writes them (the templates' filters of the same names)."""


def laptime(milliseconds: int | float | None) -> str:
    """A time in milliseconds as DeepRacer shows it: M:SS.mmm (``None`` shows as a dash)."""
    if milliseconds is None or milliseconds == "":
        return "—"
    total = round(float(milliseconds))
    minutes, rest = divmod(total, 60_000)
    seconds, millis = divmod(rest, 1000)
    return f"{minutes}:{seconds:02d}.{millis:03d}"


def clock(seconds: int | float | None) -> str:
    """A duration in seconds as M:SS, as the training clock shows it."""
    whole = max(0, round(float(seconds or 0)))
    return f"{whole // 60}:{whole % 60:02d}"


def gap(milliseconds: int | float | None) -> str:
    """The gap to first as +S.mmm (or +M:SS.mmm past a minute); first place shows a dash."""
    if not milliseconds:
        return "—"
    if milliseconds < 60_000:
        return f"+{milliseconds / 1000:.3f}"
    return f"+{laptime(milliseconds)}"
