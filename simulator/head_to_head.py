"""Model against model: two to four racers' cars on one track at once, each driven by its own
policy in its own environment, each seeing the others as DeepRacer's head-to-bot cars are seen
(its camera draws them, its lidar meets them) and crashing into them, with the evaluation's
crash penalty.

The grid is simapp's multi-agent evaluation's: car i starts 0.75 m times i behind the line
(bundle/markov/track_geom/utils.py:156-167, START_POS_OFFSET in track_geom/constants.py:22,
01f5f01), the even cars in the outer lane and the odd ones in the inner lane
(agent_ctrl/rollout_agent_ctrl.py:124-125), and by default the race ends when any car is done
(evaluation_worker.py:343, DONE_CONDITION "any"); with ``done="all"`` each car drives on until its
own race is over, and a car that has finished is parked off the field, as simapp parks it.

Each step the cars move together: every environment first learns where the others stand, then
each car takes its step. A car's own environment keeps its own trace, lap times and counts, so
each racer's results are their own.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import TYPE_CHECKING

from simulator.actors import FAR_AWAY
from simulator.config import MAX_CARS
from simulator.trace import SimTraceRow

if TYPE_CHECKING:  # the environment places itself on the grid through ``grid_place``
    from simulator.env import DeepRacerEnv
    from simulator.tracks import Track

START_OFFSET = 0.75  # [m] between one car's start and the next one's, behind it
DONE_CONDITIONS = ("any", "all")


@dataclass
class CarResult:
    """One car's race: how it ended, its laps and counts, and its trace."""

    status: str = "in_progress"
    lap_times: list[float] = field(default_factory=list)  # [s] penalties included
    progress: float = 0.0  # [%] of the lap it was on when the race ended
    counts: dict = field(default_factory=dict)  # off_tracks, crashes, resets, ...
    trace: list[SimTraceRow] = field(default_factory=list)


def grid(track: Track, cars: int) -> list[tuple[float, float]]:
    """Each car's place on simapp's grid: (metres along the track from the start, metres left of
    the centre line)."""
    return [grid_place(track, index) for index in range(cars)]


def grid_place(track: Track, index: int) -> tuple[float, float]:
    """Car ``index``'s place on simapp's grid (0 first): (metres along the track from the start,
    metres left of the centre line)."""
    inner_is_left = bool(track.project_points(track.inner[:1]).is_left[0])
    lane = track.width / 4
    inner = index % 2 == 1
    return -START_OFFSET * index, lane if inner == inner_is_left else -lane


def place_rivals(envs: Sequence[DeepRacerEnv], driving: Sequence[bool]) -> None:
    """Tell each of ``envs`` where the others' cars stand now; a car no longer ``driving`` (its
    race over) is parked off the field, as simapp parks it."""
    if len(envs) < 2:
        return
    poses = [env.body_pose if on else _parked() for env, on in zip(envs, driving, strict=True)]
    ghosts = [env.ghost for env in envs]
    for index, env in enumerate(envs):
        others = [other for other in range(len(envs)) if other != index]
        env.place_rivals([poses[other] for other in others], [ghosts[other] for other in others])


def race(
    envs: Sequence[DeepRacerEnv],
    policies: Sequence[Callable[[dict], object]],
    *,
    seed: int | None = None,
    done: str = "any",
) -> list[CarResult]:
    """Drive ``envs`` (each made with ``rivals`` = the others' number and its ``grid`` place)
    together, car i's actions from ``policies[i](observation)``, until the race is over."""
    if not 2 <= len(envs) <= MAX_CARS or len(policies) != len(envs):
        raise ValueError(f"A head-to-head race has 2 to {MAX_CARS} cars, each with its policy.")
    if done not in DONE_CONDITIONS:
        raise ValueError(f"The race ends when {' or '.join(DONE_CONDITIONS)} cars are done.")
    results = [CarResult() for _ in envs]
    observations = []
    for index, env in enumerate(envs):
        observation, info = env.reset(seed=None if seed is None else seed + index)
        observations.append(observation)
        results[index].trace.append(info["trace"])
    finished = [False] * len(envs)
    while not (any(finished) if done == "any" else all(finished)):
        place_rivals(envs, [not over for over in finished])
        for index, env in enumerate(envs):
            if finished[index]:
                continue
            observation, _, terminated, truncated, info = env.step(
                policies[index](observations[index])
            )
            observations[index] = observation
            results[index].trace.append(info["trace"])
            if terminated or truncated:
                finished[index] = True
                results[index].status = "time_up" if truncated else info["status"]
    for result, env in zip(results, envs, strict=True):
        result.lap_times = list(env.lap_times)
        result.progress = float(env.progress)
        result.counts = dict(env.counts)
        if result.status == "in_progress":
            result.status = "race_over"  # another car ended the race (DONE_CONDITION any)
    return results


def _parked() -> tuple[float, float, float]:
    return FAR_AWAY, FAR_AWAY, 0.0
