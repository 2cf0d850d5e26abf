"""A real DeepRacer model, trained in DeepRacer's simulator, driving here before and after issue
44's camera and scene: `python -m bench.bench_deepracer_model [--tracks reinvent_base,...]
[--starts 12] [--utils DIR]`.

The model is deepracer-utils' sample model (tests/deepracer/model/sample-model/model/
model_48.pb with its model_metadata.json: PPO, the 3-layer CNN on the front camera, 12 discrete
actions of 1 or 2 m/s; deepracer-utils 1.5.6, MIT, Copyright AWS DeepRacer Community). It comes
in deepracer-utils' source distribution on PyPI, which this bench fetches once with pip into
``var/`` (``python -m pip download deepracer-utils==1.5.6 --no-deps --no-binary :all:``), or
reads from ``--utils``, an unpacked copy. Its frozen graph loads as the import path loads a car
archive's (``rl.tfgraph.constants`` into ``rl.tfweights.load``).

Each track is driven from ``--starts`` points spread round the lap, one lap, in evaluation, until
the car first leaves the track (DeepRacer's evaluation with no resets): the progress [%] at the
end, averaged, for the model seeing through the camera and track image Pitlane had before issue
44 (``bench_camera_figure.BEFORE_*``), the same model through simapp's (after), and a policy
choosing among the same 12 actions at random (its seed the start's number). The tracks are
DeepRacer's (``simulator.tracks.load`` reads simapp's route files by WORLD_NAME).

``--old-parts`` finds which part of the scene the model reads: the after column is driven with
the named parts of the old look (Style fields such as ``surroundings`` or ``border_width``, or
the camera's ``room`` and ``camera_texture_ppm``) and the rest of simapp's, through simapp's
camera: ``--old-parts room,surroundings`` gives the model the old grass and sky.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import subprocess
import sys
import tarfile
import time
from pathlib import Path

import numpy as np

from bench.bench_camera_figure import BEFORE_CAMERA, BEFORE_STYLE, before
from rl import tfgraph, tfweights
from rl.networks import architecture
from rl.policies import Policy
from simulator.env import DeepRacerEnv
from simulator.texture import style_for

VERSION = "1.5.6"
MODEL = "tests/deepracer/model/sample-model/model"
TRACKS = ("reinvent_base", "reInvent2019_track", "AWS_track", "Oval_track", "Bowtie_track")


def utils_folder(given: Path | None) -> Path:
    """deepracer-utils' unpacked source: ``given``, or fetched once with pip into var/."""
    if given is not None:
        return given
    folder = Path("var") / f"deepracer_utils-{VERSION}"
    if not (folder / MODEL / "model_48.pb").exists():
        Path("var").mkdir(exist_ok=True)
        subprocess.run(
            [
                sys.executable,
                "-m",
                "pip",
                "download",
                f"deepracer-utils=={VERSION}",
                "--no-deps",
                "--no-binary",
                ":all:",
                "-d",
                "var",
                "-q",
            ],
            check=True,
        )
        with tarfile.open(Path("var") / f"deepracer_utils-{VERSION}.tar.gz") as archive:
            wanted = [m for m in archive if "/sample-model/" in m.name]
            archive.extractall("var", members=wanted, filter="data")
    return folder


def deepracer_policy(folder: Path) -> tuple[Policy, dict]:
    """model_48.pb as our policy, and the environment settings its metadata gives."""
    metadata = json.loads((folder / MODEL / "model_metadata.json").read_text())
    settings = {"sensors": metadata["sensor"], "action_space": metadata["action_space"]}
    policy = Policy.for_environment(
        "clipped_ppo", architecture(metadata["neural_network"]), {"track": TRACKS[0], **settings}
    )
    graph = tfgraph.constants((folder / MODEL / "model_48.pb").read_bytes())
    tfweights.load(policy, graph, complete=False)
    return policy, settings


def progress(env: DeepRacerEnv, act) -> float:
    """Progress [%] when the episode ends: a lap, or the car's first time off the track."""
    observation, info = env.reset(seed=0)
    done = False
    while not done:
        observation, _, terminated, truncated, info = env.step(act(observation))
        done = terminated or truncated
    return 100.0 if info["status"] == "lap_complete" else float(info["progress"])


def with_old_parts(env: DeepRacerEnv, parts: list[str]) -> DeepRacerEnv:
    """``env`` seeing ``parts`` of the scene as before issue 44, the rest as simapp's."""
    camera = {part: BEFORE_CAMERA[part] for part in parts if part in BEFORE_CAMERA}
    fields = {part: getattr(BEFORE_STYLE, part) for part in parts if part not in camera}
    env.config.update(camera, track_style=dataclasses.replace(style_for(env.track), **fields))
    env._build_sensors()  # the cameras again, from the changed config
    return env


def drive(
    track: str, settings: dict, starts: int, act_for, old: bool = False, old_parts: list[str] = ()
) -> float:
    """Mean progress from ``starts`` points round ``track``; ``act_for(start)`` gives the
    policy for each."""
    results = []
    for number in range(starts):
        env = DeepRacerEnv(
            track=track, mode="evaluation", laps=1, max_resets=0, start=number / starts, **settings
        )
        if old:
            env = before(env)
        elif old_parts:
            env = with_old_parts(env, old_parts)
        results.append(progress(env, act_for(number)))
    return float(np.mean(results))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--tracks", default=",".join(TRACKS))
    parser.add_argument("--starts", type=int, default=12, help="points round the lap")
    parser.add_argument("--utils", type=Path, help="deepracer-utils' unpacked source")
    parser.add_argument(
        "--old-parts",
        default="",
        help="drive 'after' with these parts of the old look, e.g. room,surroundings",
    )
    args = parser.parse_args()
    old_parts = [part for part in args.old_parts.split(",") if part]
    known = {*BEFORE_CAMERA, *(field.name for field in dataclasses.fields(BEFORE_STYLE))}
    if unknown := sorted(set(old_parts) - known):
        parser.error(
            f"--old-parts: no part named {', '.join(unknown)}; "
            f"the parts are {', '.join(sorted(known))}"
        )
    policy, settings = deepracer_policy(utils_folder(args.utils))
    actions = len(settings["action_space"])

    def model(_number):
        return lambda observation: int(policy.drive(observation))

    def random(number):
        rng = np.random.default_rng(number)
        return lambda _observation: int(rng.integers(actions))

    started = time.perf_counter()
    print(
        f"deepracer-utils {VERSION} model_48.pb, {args.starts} starts a track, one lap, "
        "ended at the first time off the track: mean progress [%]"
    )
    if old_parts:
        print(f"after: simapp's camera and scene but the old {', '.join(old_parts)}")
    print(f"{'track':<22}{'random':>8}{'before':>8}{'after':>8}")
    for track in args.tracks.split(","):
        row = [
            drive(track, settings, args.starts, random),
            drive(track, settings, args.starts, model, old=True),
            drive(track, settings, args.starts, model, old_parts=old_parts),
        ]
        print(f"{track:<22}" + "".join(f"{value:8.1f}" for value in row), flush=True)
    print(f"({time.perf_counter() - started:.0f} s)")


if __name__ == "__main__":
    main()
