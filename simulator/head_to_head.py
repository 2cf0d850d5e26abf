"""Model against model: two to four racers' cars on one track at once, each driven by its own
policy in its own environment, each seeing the others as DeepRacer's head-to-bot cars are seen
(its camera draws them, its lidar meets them) and crashing into them, with the evaluation's
crash penalty.

The grid is simapp's multi-agent evaluation's: car i starts 0.75 m times i behind the line
(bundle/markov/track_geom/utils.py:156-167, START_POS_OFFSET in track_geom/constants.py:22,
01f5f01), the even cars in the outer lane and the odd ones in the inner lane
(agent_ctrl/rollout_agent_ctrl.py:124-125); a car that has finished is parked off the field, as
simapp parks it, while the others drive on.

The race is driven by the one episode loop (``rl.episode.Fleet`` with ``race=True``, as
``jobs.evaluation.Race`` drives it): each step every environment first learns where the others
stand (``place_rivals``), then each car takes its step. A car's own environment keeps its own
trace, lap times and counts, so each racer's results are their own.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import TYPE_CHECKING

from simulator.actors import FAR_AWAY

if TYPE_CHECKING:  # the environment places itself on the grid through ``grid_place``
    from simulator.env import DeepRacerEnv
    from simulator.tracks import Track

START_OFFSET = 0.75  # [m] between one car's start and the next one's, behind it


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


def _parked() -> tuple[float, float, float]:
    return FAR_AWAY, FAR_AWAY, 0.0
