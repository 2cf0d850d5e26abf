"""Racers' reward functions: the examples we offer, the params they read, and validation.

Validation is what the console's "Validate" button and ``manage.py validate_reward`` run: static
checks that give feedback with line numbers (size, syntax, imports, the function's signature),
then the function itself, in the sandbox, on sample situations from the chosen track. The static
checks are for feedback only; the sandbox is what keeps the code in its box.

Long because the params' table (each name, its type and DeepRacer's words for it) and the examples'
descriptions are data that the editor and the help page read from here.
"""

from __future__ import annotations

import ast
import difflib
import re
import time
from collections.abc import Mapping
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

from common.transactions import outside_transaction
from sandbox import Sandbox, SandboxFailure, verified

ALLOWED_IMPORTS = ("math", "random", "numpy", "scipy", "shapely")
MAX_SOURCE_SIZE = 140_000  # [characters]
# [s] per sample call: training's own limit (jobs.rollouts.REWARD_CALL_LIMIT), which stops a
# slower function anyway; 5 s before issue 55 let a flood of such functions hold every checker
# for 30 s a check.
SAMPLE_TIMEOUT = 1.0
# [s] the code's load and samples together: once spent, the samples left are not run (a warning
# says so), so that no check holds a checker (training.checkers) much longer than this and the
# sandbox's start.
SAMPLES_BUDGET = 2.0
NESTED_TOO_DEEP = (
    "The code is nested too deeply for Python to read: split long expressions and deep blocks "
    "into smaller parts."
)
EXAMPLES_DIR = Path(__file__).resolve().parent / "reward_examples"


@dataclass(frozen=True)
class Example:
    slug: str
    title: str
    explanation: str

    @property
    def source(self) -> str:
        return (EXAMPLES_DIR / f"{self.slug}.py").read_text()


EXAMPLES = (
    Example(
        "follow_centre_line",
        "Follow the centre line",
        "Rewards the car for staying near the centre line: three bands, each worth less than "
        "the one inside it. The default, and the place to start.",
    ),
    Example(
        "stay_inside_borders",
        "Stay inside the borders",
        "Rewards every step on which all four wheels are inside the borders, whatever the "
        "line. The car finds its own racing line.",
    ),
    Example(
        "prevent_zig_zag",
        "Prevent zig-zag",
        "Follows the centre line, and takes reward away when the steering is above a "
        "threshold, for a smoother drive.",
    ),
    Example(
        "follow_racing_line",
        "Follow the racing line",
        "Rewards the car for driving near a racing line at the line's speed there. It holds "
        "reInvent2019_track's line: paste your track's over it, from the track's page.",
    ),
    Example(
        "avoid_objects",
        "Avoid objects",
        "For object avoidance and head-to-bot races: stay on the track, and keep out of the "
        "lane of the next object ahead, the more so the closer it is.",
    ),
)


def example_source(slug: str) -> str:
    """The code of the example ``slug`` names (``EXAMPLES``)."""
    return next(example for example in EXAMPLES if example.slug == slug).source


# The input parameters, as DeepRacer documents them.
PARAMS = (
    ("all_wheels_on_track", "bool", "All four wheels are inside the track borders."),
    (
        "x",
        "float",
        "Position in metres (x): the point 0.14 m ahead of the middle between the axles.",
    ),
    ("y", "float", "Position in metres (y)."),
    ("heading", "float", "Yaw in degrees, -180 to 180, in the track's frame."),
    ("distance_from_center", "float", "Metres from the car's position to the centre line."),
    ("is_left_of_center", "bool", "Left of the centre line in the direction of travel."),
    ("is_offtrack", "bool", "No wheel is on the track; the episode ends."),
    ("is_crashed", "bool", "The car hit an object or a bot car."),
    ("is_reversed", "bool", "The track is driven clockwise (not: the car drives backwards)."),
    ("progress", "float", "Per cent of the lap completed, 0 to 100."),
    (
        "steps",
        "float",
        "Steps in this episode, counted as DeepRacer does: step 1 is the start, so the first "
        "call sees 2.0; 15 steps are one second.",
    ),
    ("speed", "float", "The commanded speed of the chosen action, in m/s."),
    (
        "steering_angle",
        "float",
        "The commanded steering of the chosen action, in degrees; positive is left.",
    ),
    ("track_width", "float", "Track width in metres, measured across the nearest centre point."),
    ("track_length", "float", "Length of the centre line in metres."),
    ("waypoints", "list[(x, y)]", "Centre-line points; a loop repeats its first at the end."),
    (
        "closest_waypoints",
        "[int, int]",
        "Indices of the waypoints behind and ahead of the car; on waypoint i: [i, i + 1].",
    ),
    ("projection_distance", "float", "Metres along the centre line from the start line."),
    ("sim_time", "float", "The simulation clock in seconds; it runs on from episode to episode."),
    (
        "closest_objects",
        "[int, int]",
        "Indices of the objects behind and ahead; [0, 0] when there are none.",
    ),
    ("objects_location", "list[[x, y]]", "Positions of the objects and bot cars; [] if none."),
    (
        "objects_distance",
        "list[float]",
        "Each object's distance along the centre line from the start line.",
    ),
    ("objects_distance_from_center", "list[float]", "Each object's distance from the centre line."),
    (
        "objects_heading",
        "list[float]",
        "Each object's heading in radians when the race has bot cars; 0.0 otherwise.",
    ),
    ("objects_left_of_center", "list[bool]", "Whether each object is left of the centre line."),
    (
        "objects_speed",
        "list[float]",
        "The bot cars' speed in m/s for every object when the race has bot cars; 0.0 otherwise.",
    ),
    (
        "object_in_camera",
        "bool",
        "The next object ahead is in the front camera's view; False when there are none.",
    ),
)


@dataclass
class Problem:
    type: str  # "syntax", "import", "key" or "test failure" (errors); "style", "slow" (warnings)
    message: str
    line: int | None = None


@dataclass
class Sample:
    situation: str
    description: str
    reward: float | None
    error: str | None = None


@dataclass
class Validation:
    source: str = ""  # the code validated
    errors: list[Problem] = field(default_factory=list)
    warnings: list[Problem] = field(default_factory=list)
    samples: list[Sample] = field(default_factory=list)
    log: list[str] = field(default_factory=list)

    @property
    def valid(self) -> bool:
        return not self.errors

    def as_dict(self) -> dict:
        return {
            "valid": self.valid,
            "errors": [asdict(problem) for problem in self.errors],
            "warnings": [asdict(problem) for problem in self.warnings],
            "samples": [asdict(sample) for sample in self.samples],
            "log": self.log,
        }


def reward_validate(
    *, source: str, track: str | Mapping[str, Any], direction: str = "counterclockwise"
) -> Validation:
    """Check ``source`` statically, then run it in the sandbox on sample situations of ``track``
    (a name, or its inline form, ``simulator.tracks.inline``, which needs no database)."""
    outside_transaction("A reward function's validation in the sandbox")
    result = Validation(source)
    result.errors, result.warnings = static_problems(source)
    if result.errors:
        return result
    verified()  # SandboxUnavailable where racers' code cannot be held safely
    where = {"track": track, "direction": direction}
    with Sandbox(call_timeout=SAMPLE_TIMEOUT, samples=where) as sandbox:
        budget_ends = time.monotonic() + SAMPLES_BUDGET
        try:
            sandbox.load(source)
        except SandboxFailure as failure:
            result.errors.append(_problem_for(failure))
            return result
        samples = sandbox.situations()
        failed: dict[tuple[str, str, int | None], list[str]] = {}
        for number, situation in enumerate(samples):
            if time.monotonic() > budget_ends:
                problems = result.warnings if number else result.errors  # none run: not valid
                problems.append(_budget_spent(samples[number:], number))
                break
            name, description = situation["name"], situation["description"]
            try:
                reward = sandbox.call(situation["params"])
            except SandboxFailure as failure:
                problem = _problem_for(failure)
                failed.setdefault((problem.type, problem.message, problem.line), []).append(name)
                result.samples.append(Sample(name, description, None, problem.message))
                if failure.kind in ("crashed", "timeout", "protocol"):
                    break  # the sandbox is gone; the remaining samples cannot run
                continue
            result.samples.append(Sample(name, description, reward))
        result.log = list(sandbox.logs)
    for (kind, message, line), names in failed.items():
        result.errors.append(Problem(kind, f"{_where(names, len(samples))}: {message}", line))
    return result


def _budget_spent(left: list[dict], run: int) -> Problem:
    """The problem of the samples ``left`` unrun once the first ``run`` spent the budget."""
    names = ", ".join(situation["name"] for situation in left)
    what = f"the first {run} samples" if run else "the module (no sample could be run)"
    return Problem(
        "slow",
        f"Loading the code and {what} took more than {SAMPLES_BUDGET:g} s, so {names} were not "
        "run: a training step calls the function several times a second.",
    )


def _where(names: list[str], total: int) -> str:
    """Which samples a failure happened in: one problem for the same failure in several."""
    if len(names) == 1:
        return f"In the {names[0]} sample"
    if len(names) == total:
        return f"In all {total} samples"
    listed = ", ".join(names[:-1]) + " and " + names[-1]
    return f"In {len(names)} of the {total} samples ({listed})"


def static_problems(source: str) -> tuple[list[Problem], list[Problem]]:
    """(errors, warnings) that can be told without running the code."""
    if len(source) > MAX_SOURCE_SIZE:
        return [
            Problem(
                "syntax",
                f"The reward function is {len(source):,} characters long; "
                f"the limit is {MAX_SOURCE_SIZE:,}.",
            )
        ], []
    try:
        tree = ast.parse(source, filename="<reward_function>")
    except SyntaxError as error:
        return [Problem("syntax", _syntax_message(error), error.lineno)], []
    except (MemoryError, RecursionError):  # the parser's own limits, not Python's grammar
        return [Problem("syntax", NESTED_TOO_DEEP)], []
    errors: list[Problem] = []
    warnings: list[Problem] = []
    for node in ast.walk(tree):
        if isinstance(node, ast.Import | ast.ImportFrom):
            errors.extend(_import_problems(node))
        elif isinstance(node, ast.Call) and isinstance(node.func, ast.Name):
            if node.func.id == "__import__":
                errors.append(
                    Problem("import", "Use an import statement, not __import__().", node.lineno)
                )
            elif node.func.id == "print":
                warnings.append(
                    Problem(
                        "style",
                        "print() runs on every step and slows training; "
                        "its output goes to the training log.",
                        node.lineno,
                    )
                )
    errors.extend(_signature_problems(tree))
    key_errors, key_warnings = _params_key_problems(tree)
    return errors + key_errors, warnings + key_warnings


def _import_problems(node: ast.Import | ast.ImportFrom) -> list[Problem]:
    allowed = ", ".join(ALLOWED_IMPORTS[:-1]) + " and " + ALLOWED_IMPORTS[-1]
    if isinstance(node, ast.ImportFrom) and (node.level or not node.module):
        return [
            Problem(
                "import", f"Relative imports are not allowed; import from {allowed}.", node.lineno
            )
        ]
    names = [node.module] if isinstance(node, ast.ImportFrom) else [a.name for a in node.names]
    return [
        Problem("import", f"Only {allowed} may be imported, not {name.split('.')[0]}.", node.lineno)
        for name in names
        if name.split(".")[0] not in ALLOWED_IMPORTS
    ]


def _signature_problems(tree: ast.Module) -> list[Problem]:
    functions = [
        node
        for node in tree.body
        if isinstance(node, ast.FunctionDef | ast.AsyncFunctionDef)
        and node.name == "reward_function"
    ]
    if not functions:
        return [Problem("syntax", "Define reward_function(params) at the top level of the code.")]
    function = functions[-1]
    arguments = function.args
    positional = arguments.posonlyargs + arguments.args
    required = len(positional) - len(arguments.defaults)
    if isinstance(function, ast.AsyncFunctionDef):
        return [
            Problem(
                "syntax", "reward_function must be a plain def, not async def.", function.lineno
            )
        ]
    if not positional or required > 1 or arguments.vararg or arguments.kwonlyargs:
        return [
            Problem(
                "syntax", "reward_function must take exactly one argument: params.", function.lineno
            )
        ]
    return []


def _syntax_message(error: SyntaxError) -> str:
    message = error.msg[0].upper() + error.msg[1:] if error.msg else "Invalid syntax"
    if error.text and error.text.strip():
        message += f": {error.text.strip()[:80]}"
    return message


PARAM_NAMES = tuple(name for name, _, _ in PARAMS)
KEY_ERROR = re.compile(r"KeyError: '([^'\\]*)'")


def unknown_key_message(key: str) -> str:
    """What to say about ``params[key]`` for a key params does not have: the closest real key."""
    close = difflib.get_close_matches(key, PARAM_NAMES, n=1, cutoff=0.6)
    if close:
        return f"params has no key '{key}'; did you mean '{close[0]}'?"
    return f"params has no key '{key}'; its keys are listed under Input parameters."


def _params_key_problems(tree: ast.Module) -> tuple[list[Problem], list[Problem]]:
    """Keys of params that DeepRacer never sends, read by ``params["..."]`` (an error: it fails
    whenever that line runs) or ``params.get("...")`` (a warning: it always gives its default)."""
    names = {"params"}
    for node in tree.body:
        if isinstance(node, ast.FunctionDef) and node.name == "reward_function":
            names.update(a.arg for a in (node.args.posonlyargs + node.args.args)[:1])
    errors: list[Problem] = []
    warnings: list[Problem] = []
    for node in ast.walk(tree):
        if (
            isinstance(node, ast.Subscript)
            and isinstance(node.value, ast.Name)
            and node.value.id in names
            and isinstance(node.slice, ast.Constant)
            and isinstance(node.slice.value, str)
            and node.slice.value not in PARAM_NAMES
        ):
            errors.append(Problem("key", unknown_key_message(node.slice.value), node.lineno))
        elif (
            isinstance(node, ast.Call)
            and isinstance(node.func, ast.Attribute)
            and node.func.attr == "get"
            and isinstance(node.func.value, ast.Name)
            and node.func.value.id in names
            and node.args
            and isinstance(node.args[0], ast.Constant)
            and isinstance(node.args[0].value, str)
            and node.args[0].value not in PARAM_NAMES
        ):
            key = node.args[0].value
            warnings.append(
                Problem(
                    "style",
                    f"{node.func.value.id}.get('{key}') always gives its default, since "
                    + unknown_key_message(key),
                    node.lineno,
                )
            )
    return errors, warnings


def _problem_for(failure: SandboxFailure) -> Problem:
    kind = {"syntax": "syntax", "import": "import"}.get(failure.kind, "test failure")
    message = failure.message
    missing = KEY_ERROR.fullmatch(message)
    key = missing.group(1) if missing else None
    if key and key not in PARAM_NAMES and difflib.get_close_matches(key, PARAM_NAMES, cutoff=0.6):
        kind, message = "key", unknown_key_message(key)  # a typo, not a local dict's key
    return Problem(kind, message, failure.line)
