"""Training throughput and time to qualify: `python -m bench.bench_training [--qualify [--fast]]`.

Starts the whole console as `make run` does (its Redis, a Celery worker with enough processes for
a trainer and two rollout workers, the database in a scratch directory), creates models with all
of DeepRacer's defaults (the beginner track, the follow-the-centre-line reward function, PPO
defaults, the default discrete action space, the camera) and lets them train.

- Throughput: environment steps per second over 20 minutes of training (``--minutes``), policy
  updates included, with 1 and with 2 rollout workers, per iteration with where its time went,
  and the mean over the iterations whose training episodes completed a lap.
- With --update, the policy update alone: milliseconds per environment step, as Pitlane learns,
  with PyTorch's stock layers, and with the changes tried and not adopted (channels-last
  tensors, torch.compile), on one thread and on all.
- Time to qualify (--qualify): for each seed, train; every time a new checkpoint appears, drive
  it (deterministically, outside training) in an evaluation of 3 laps; the figure is the training
  minutes until a checkpoint drives 3 consecutive laps without leaving the track.
- With --fast, a racer's model instead: a continuous action space up to 4 m/s (``--speed``) and a
  speed-aware reward (``FAST_REWARD``, or with ``--reward steady`` the same with steady hands,
  ``STEADY_REWARD``, or with ``--reward aligned`` that with a steady heading too,
  ``ALIGNED_REWARD``); besides the time to qualify, the fastest lap the first checkpoint past
  ``--lap-after`` training minutes drives, and the model's then (training stopped there, its
  best checkpoint: what DeepRacer races and downloads), beside the braking driver's lap on the
  same track, and each checkpoint's exploration spread. ``--under`` asks for 3 clean laps each
  under a time: the time to a lap time. ``--workers N`` trains with N rollout workers (1 unless
  said), as a racer's model may.
"""

from __future__ import annotations

import argparse
import os
import time

from bench.stack import running_console
from rl.hyperparameters import PPO, SAC

THROUGHPUT_MINUTES = 20.0
CHECK_LATE_EVALUATIONS = 5.0  # [s] after the stop, for the evaluation results still coming
QUALIFY_LIMIT_MINUTES = 30.0
LAP_AFTER_MINUTES = 20.0
LATE_CHECKPOINT = 5.0  # [min] past --lap-after, the longest an iteration's checkpoint takes
FAST_SPEED = (0.5, 4.0)  # [m/s] the --fast model's speed range, unless --speed says otherwise
FAST_REWARD = """\
import math


def reward_function(params):
    # Stay near the centre line and drive at the speed the road ahead allows, as a racer reading
    # the waypoints would: each bend in the next 3 m allows the speed at which turning takes
    # 3 m/s^2, plus what braking at 3 m/s^2 sheds on the way to it. Below that speed the reward
    # grows with the speed squared and above it falls fast, so a whole lap pays most at it.
    if params["is_offtrack"] or not params["all_wheels_on_track"]:
        return 1e-3
    waypoints = params["waypoints"]
    count = len(waypoints) - 1 if waypoints[0] == waypoints[-1] else len(waypoints)
    stride = max(1, round(0.3 / math.dist(waypoints[0], waypoints[1])))  # about 0.3 m
    index = params["closest_waypoints"][1]
    target, travelled = 4.0, math.dist((params["x"], params["y"]), waypoints[index])
    while travelled < 3.0:
        a, b, c = (waypoints[(index + k) % count] for k in (-stride, 0, stride))
        area = abs((b[0] - a[0]) * (c[1] - a[1]) - (c[0] - a[0]) * (b[1] - a[1])) / 2
        radius = math.dist(a, b) * math.dist(b, c) * math.dist(a, c) / (4 * area or 1e-12)
        target = min(target, math.sqrt(3.0 * radius + 2 * 3.0 * travelled))
        travelled += math.dist(b, waypoints[(index + 1) % count])
        index += 1
    speed = params["speed"]
    pace = (speed / target) ** 2 if speed <= target else max(1.0 - (speed - target) ** 2, 0.0)
    off_centre = params["distance_from_center"] / (params["track_width"] / 2)
    return max(1.0 - off_centre**2, 0.0) * pace + 1e-3
"""
# The road-ahead reward with steady hands: a racer's stateful reward (its module lives as long as
# the worker, as DeepRacer's does) that also pays less the more the steering command changed since
# the last step. Each new command kicks the steering hinge and the rest of it closes over half a
# second, so a shaken command throws the car off the line a little late for the road-ahead reward
# to say which command did it; this factor says so at once.
STEADY_REWARD = (
    FAST_REWARD
    + """

_last = {"steps": None, "steering": 0.0}
_road_ahead = reward_function


def reward_function(params):
    steps, steering = params["steps"], params["steering_angle"]
    change = abs(steering - _last["steering"]) if _last["steps"] == steps - 1 else 0.0
    _last.update(steps=steps, steering=steering)
    return _road_ahead(params) * max(1.0 - (change / 30.0) ** 2, 0.0) + 1e-3
"""
)
# Steady hands and a steady heading: the car's heading against the track's direction at the
# closest waypoints (DeepRacer's own example reward 3 reads the same params) also lowers the
# reward, so weaving costs at once what it costs later in distance from the centre.
ALIGNED_REWARD = (
    STEADY_REWARD
    + """

_steady = reward_function


def reward_function(params):
    waypoints, (behind, ahead) = params["waypoints"], params["closest_waypoints"]
    dx, dy = (waypoints[ahead][k] - waypoints[behind][k] for k in (0, 1))
    off = abs((math.degrees(math.atan2(dy, dx)) - params["heading"] + 180) % 360 - 180)
    return _steady(params) * max(1.0 - (off / 30.0) ** 2, 0.0) + 1e-3
"""
)
REWARDS = {"road-ahead": FAST_REWARD, "steady": STEADY_REWARD, "aligned": ALIGNED_REWARD}


def bench_racer(name: str = "bench"):
    """A benchmark's racer, with a quota no benchmark reaches."""
    from django.contrib.auth.models import User

    from training.models import Quota

    owner = User.objects.create_user(name, password="bench-password-1")  # noqa: S106
    Quota.objects.create(racer=owner, max_models=1_000, max_minutes_per_month=1_000_000)
    return owner


def default_model(
    owner, name: str, *, workers: int = 1, seed: int = 0, fast: bool = False,
    steering: float = 30, speed: tuple[float, float] = FAST_SPEED, algorithm: str = PPO,
    hyperparameters: dict | None = None, reward: str = "road-ahead",
):  # fmt: skip
    """A model with DeepRacer's defaults on the Rookie Loop; ``hyperparameters``: the racer's
    own values of some (DeepRacer's names), over the algorithm's defaults; with ``fast``,
    ``reward`` names the reward function (``REWARDS``)."""
    from rl.hyperparameters import defaults
    from training.rewards import EXAMPLES
    from training.services import model_create

    settings = {
        "name": name,
        "track": "rookie-loop",
        "reward_function": EXAMPLES[0].source,
        "workers": workers,
        "seed": seed,
        "max_minutes": 1440,
    }
    if fast:
        actions = {
            "steering_angle": {"low": -steering, "high": steering},
            "speed": {"low": speed[0], "high": speed[1]},
        }
        settings.update(action_space=actions, reward_function=REWARDS[reward], algorithm=algorithm)
    if hyperparameters:
        settings["hyperparameters"] = {**defaults(algorithm if fast else PPO), **hyperparameters}
    return model_create(owner=owner, settings=settings)


def job_of(model):
    from training.models import TrainingJob

    return TrainingJob.objects.get(model=model)


def throughput(owner, workers: int, minutes: float) -> None:
    """Train a default model for ``minutes``; print each iteration's steps/s and where its time
    went, then the mean over all iterations and over those whose training episodes lapped."""
    from rl.stopwatch import PHASES
    from training.models import Iteration
    from training.services import training_stop

    model = default_model(owner, f"throughput-{workers}", workers=workers)
    while job_of(model).status != "IN_PROGRESS":
        time.sleep(1)
    time.sleep(minutes * 60)
    job = job_of(model)
    training_stop(job=job)
    while job_of(model).status != "COMPLETED":
        time.sleep(1)
    time.sleep(CHECK_LATE_EVALUATIONS)
    rows = list(Iteration.objects.filter(job=job).order_by("number"))
    print(f"{workers} rollout worker(s), {minutes:g} min, {len(rows)} iterations:")
    print("  iter  steps  wall s  steps/s  lap  " + "  ".join(f"{p:>8}" for p in PHASES)
          + "  eval s")  # fmt: skip
    for row in rows:
        split = "  ".join(f"{row.time_split.get(p, 0.0):8.1f}" for p in PHASES)
        evaluation = f"{row.evaluation_seconds:6.1f}" if row.evaluation_seconds else "     —"
        print(f"  {row.number:4d}  {row.steps:5d}  {row.wall_seconds:6.1f}  "
              f"{row.steps / row.wall_seconds:7.1f}  {'yes' if row.best_lap_time else ' no'}  "
              f"{split}  {evaluation}")  # fmt: skip

    def rate(chosen: list) -> str:
        wall = sum(row.wall_seconds for row in chosen)
        return f"{sum(row.steps for row in chosen) / wall:.1f} steps/s" if wall else "—"

    lapping = [row for row in rows if row.best_lap_time]
    print(f"  mean: {rate(rows)}; over the {len(lapping)} iterations that lapped: "
          f"{rate(lapping)}", flush=True)  # fmt: skip


def update_speed(steps: int = 2000) -> None:
    """[ms] a PPO update takes per environment step, DeepRacer's defaults (3-layer CNN, camera,
    10 epochs of minibatches of 64) on random camera frames: as Pitlane learns, with the first
    convolution and Adam as PyTorch's stock layers run them, and with the changes tried and not
    adopted (channels-last tensors, torch.compile), on one thread and on all."""
    import gymnasium
    import numpy as np
    import torch
    from torch import nn

    import simulator
    from rl import hyperparameters, networks
    from rl.experience import Episode
    from rl.learner import Learner

    env = gymnasium.make(simulator.ENV_ID, track="rookie-loop")
    spaces = env.observation_space, env.action_space
    env.close()
    rng = np.random.default_rng(0)
    per_episode = 100
    frames = {
        name: rng.integers(0, 256, (per_episode + 1, *space.shape), dtype=np.uint8)
        for name, space in spaces[0].spaces.items()
    }

    def episode() -> Episode:
        return Episode(
            worker=0, version=0, observations=frames,
            actions=rng.integers(0, spaces[1].n, per_episode),
            rewards=rng.random(per_episode, dtype=np.float32),
            values=rng.random(per_episode, dtype=np.float32),
            log_probs=np.full(per_episode, -2.3, np.float32), terminated=True, final_value=0.0,
            progress=10.0, status="off_track", lap_time=None, trace=[],
        )  # fmt: skip

    episodes = [episode() for _ in range(steps // per_episode)]

    def stock(built: Learner) -> None:
        policy = built.model.policy
        for module in policy.modules():
            if isinstance(module, networks.CameraConv2d):
                module.__class__ = nn.Conv2d
        policy.optimizer = torch.optim.Adam(policy.parameters(), lr=policy.optimizer.
                                            param_groups[0]["lr"], eps=1e-5)  # fmt: skip

    def channels_last(built: Learner) -> None:
        built.model.policy.to(memory_format=torch.channels_last)

    def compiled(built: Learner) -> None:
        policy = built.model.policy
        policy.pi_features_extractor = torch.compile(policy.pi_features_extractor)
        policy.vf_features_extractor = torch.compile(policy.vf_features_extractor)

    variants = {  # tried and measured; what Pitlane adopts is "Pitlane"
        "stock layers": stock,
        "Pitlane": lambda built: None,
        "Pitlane, channels last": channels_last,
        "Pitlane, torch.compile": compiled,
    }
    print(f"PPO update, DeepRacer's defaults, {steps} steps [ms per step; warm-up s]:")
    for threads in sorted({1, os.cpu_count() or 1}):
        torch.set_num_threads(threads)
        for name, change in variants.items():
            built = Learner(
                algorithm=PPO, hyperparameters=hyperparameters.defaults(PPO),
                architecture=networks.SHALLOW, observation_space=spaces[0],
                action_space=spaces[1],
            )  # fmt: skip
            change(built)
            started = time.perf_counter()
            built.learn(episodes[:2])  # warm up (and compile)
            warm_up = time.perf_counter() - started
            started = time.perf_counter()
            built.learn(episodes)
            took = (time.perf_counter() - started) / steps * 1000
            print(f"  {threads} thread(s), {name}: {took:.1f}; {warm_up:.1f}", flush=True)


def qualifies(model, checkpoint: str) -> tuple[bool, list[float], str]:
    """Drive ``checkpoint`` for 3 laps in an evaluation; (no off-track or crash, the lap times,
    its policy's spread as ``spread`` words it)."""
    import gymnasium

    import simulator
    from rl.learner import Learner
    from training import artifacts

    env = gymnasium.make(
        simulator.ENV_ID, mode="evaluation", laps=3, **model.environment_settings()
    )
    learner = Learner(
        algorithm=model.algorithm,
        hyperparameters=model.hyperparameters,
        architecture=model.architecture,
        observation_space=env.observation_space,
        action_space=env.action_space,
    )
    learner.restore(artifacts.read(checkpoint))
    observation, _ = env.reset(seed=0)
    while True:
        action, _ = learner.model.policy.predict(observation, deterministic=True)
        observation, _, terminated, truncated, info = env.step(action)
        if info["resets"] or terminated or truncated:
            break  # a reset (off track, crash, reversed, stuck) ends the consecutive laps
    clean = len(info["lap_times"]) == 3 and not info["resets"]
    return clean, info["lap_times"], spread(learner.model.policy)


def laps_words(laps: list[float]) -> str:
    return ", ".join(f"{t:.2f}" for t in laps) or "none"


def lap_words(lap: float | None) -> str:
    return f"{lap:.2f} s" if lap else "no 3 clean laps"


def racers_model(model) -> tuple[bool, list[float], int | None]:
    """Drive what the racer's model is once its training has stopped: its job's best checkpoint,
    the one DeepRacer races and downloads. simapp (01f5f01): a race drives the best checkpoint
    (bundle/markov/virtual_event/virtual_event_agent_data.py:230), and the model.pb a finished
    training leaves is the best's (bundle/markov/boto/s3/files/checkpoint_files/
    tensorflow_model.py:329-365). (no off-track or crash in 3 laps, the lap times, the
    checkpoint's iteration)."""
    from training import artifacts

    while (job := job_of(model)).status in job.ACTIVE:
        time.sleep(1)
    ok, laps, _ = qualifies(model, job.best_checkpoint)
    return ok, laps, artifacts.checkpoint_iteration(job.best_checkpoint)


def spread(policy) -> str:
    """A continuous policy's exploration: each action's standard deviation, as a share of half
    its range (1 at the start); empty for a discrete one, and for SAC's (its spread depends on
    what the car sees)."""
    log_std = getattr(policy, "log_std", None)
    if log_std is None:
        return ""
    steering, speed = log_std.detach().exp().tolist()
    return f"; spread: steering {steering:.2f}, speed {speed:.2f}"


def time_to_qualify(
    owner,
    seed: int,
    limit: float,
    *,
    fast: bool = False,
    lap_after: float = LAP_AFTER_MINUTES,
    steering: float = 30,
    speed: tuple[float, float] = FAST_SPEED,
    under: float | None = None,
    algorithm: str = PPO,
    hyperparameters: dict | None = None,
    reward: str = "road-ahead",
    workers: int = 1,
) -> tuple[float | None, float | None, float | None]:
    """(training minutes to qualify or None, with --fast the best lap of the first checkpoint
    after ``lap_after`` minutes and that of the model then, its best checkpoint; a lap only where
    3 were clean); a fast model trains on to ``lap_after`` once it qualifies.
    With ``under``, qualifying takes 3 clean laps each under that many seconds; ``workers``: the
    model's rollout workers."""
    from training.services import training_stop

    model = default_model(owner, f"qualify-{seed}{'-fast' if fast else ''}", seed=seed, fast=fast,
                          steering=steering, speed=speed, algorithm=algorithm,
                          hyperparameters=hyperparameters, reward=reward,
                          workers=workers)  # fmt: skip
    tried = set()
    qualified = None
    while True:
        job = job_of(model)
        minutes = job.training_seconds / 60
        if job.last_checkpoint and job.last_checkpoint not in tried and job.iterations > 0:
            tried.add(job.last_checkpoint)
            ok, laps, spread_words = qualifies(model, job.last_checkpoint)
            ok = ok and (under is None or max(laps) < under)
            print(
                f"  seed {seed}: iteration {job.iterations} after {minutes:.1f} min: "
                + (
                    f"qualified, laps {laps_words(laps)}"
                    if ok
                    else f"not yet ({len(laps)} clean laps"
                    + (f": {laps_words(laps)})" if laps else ")")
                )
                + spread_words,
                flush=True,
            )
            if ok and qualified is None:
                qualified = minutes
            if qualified is not None and (not fast or under is not None):
                training_stop(job=job)  # the time to qualify (or to the lap time) is known
                return qualified, (min(laps) if fast else None), None
            if fast and minutes >= lap_after:
                training_stop(job=job)
                model_ok, model_laps, iteration = racers_model(model)
                print(f"  seed {seed}: the model, its best checkpoint (iteration {iteration}): "
                      f"{'3' if model_ok else 'not 3'} clean laps: {laps_words(model_laps)}",
                      flush=True)  # fmt: skip
                best_lap, model_lap = (
                    min(laps) if ok else None,
                    min(model_laps) if model_ok else None,
                )
                return qualified, best_lap, model_lap
        # With --fast the lap is the first checkpoint's after lap_after, which may land a whole
        # iteration after it: wait for it (up to LATE_CHECKPOINT more minutes).
        lapping = fast and under is None
        if minutes > (max(limit, lap_after + LATE_CHECKPOINT) if lapping else limit):
            training_stop(job=job)
            return qualified, None, None
        time.sleep(5)


def _setting(text: str) -> tuple[str, float]:
    name, _, value = text.partition("=")
    try:
        return name, float(value)
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r} is not NAME=NUMBER") from None


def main() -> None:
    parser = argparse.ArgumentParser()
    parser.add_argument("--qualify", action="store_true", help="measure the time to qualify")
    parser.add_argument(
        "--update", action="store_true", help="time the policy update alone, without a console"
    )
    parser.add_argument(
        "--steps", type=int, default=2000, help="with --update, the steps learnt from"
    )
    parser.add_argument(
        "--minutes",
        type=float,
        default=THROUGHPUT_MINUTES,
        help="[min] of training for the throughput",
    )
    parser.add_argument(
        "--workers", type=int, nargs="+", default=None,
        help="rollout workers: for throughput, each count in turn (default 1 and 2); with "
        "--qualify, the model's (one count, default 1)",
    )  # fmt: skip
    parser.add_argument(
        "--fast",
        action="store_true",
        help="a continuous action space to 4 m/s and a speed-aware reward",
    )
    parser.add_argument(
        "--lap-after",
        type=float,
        default=LAP_AFTER_MINUTES,
        help="[min] of training after which --fast reports the best lap",
    )
    parser.add_argument(
        "--steering", type=float, default=30, help="[deg] with --fast, the steering range's bound"
    )
    parser.add_argument(
        "--speed", type=float, nargs=2, default=FAST_SPEED, metavar=("LOW", "HIGH"),
        help="[m/s] with --fast, the speed range",
    )  # fmt: skip
    parser.add_argument(
        "--reward", choices=tuple(REWARDS), default="road-ahead",
        help="with --fast, the reward function: the road ahead's speed, that with steady hands, "
        "or that with a steady heading too",
    )  # fmt: skip
    parser.add_argument(
        "--under", type=float, default=None,
        help="[s] qualifying takes 3 clean laps each under this time",
    )  # fmt: skip
    parser.add_argument(
        "--algorithm", choices=(PPO, SAC), default=PPO,
        help="with --fast, PPO (DeepRacer's default) or SAC",
    )  # fmt: skip
    parser.add_argument(
        "--hyperparameter", type=_setting, action="extend", nargs="+", default=[],
        metavar="NAME=VALUE", help="with --qualify, a racer's own value (DeepRacer's names)",
    )  # fmt: skip
    parser.add_argument("--seeds", type=int, nargs="+", default=[0, 1, 2])
    parser.add_argument(
        "--limit",
        type=float,
        default=QUALIFY_LIMIT_MINUTES,
        help="[min] of training after which a seed is given up",
    )
    arguments = parser.parse_args()
    if arguments.qualify and arguments.workers and len(arguments.workers) > 1:
        parser.error("with --qualify, --workers takes one count: the model's rollout workers")
    if arguments.update:
        os.environ.setdefault("DJANGO_SETTINGS_MODULE", "console.settings.dev")
        import django

        django.setup()
        update_speed(arguments.steps)
        return
    with running_console(concurrency=3) as console:
        os.environ.update(console["env"])
        import django

        django.setup()

        owner = bench_racer()
        if arguments.qualify:
            under = f", each under {arguments.under:g} s" if arguments.under else ""
            print(f"Time to qualify (3 clean consecutive laps{under}), training minutes:")
            if arguments.fast:
                from bench.bench_simulator import braking_lap

                print(f"The braking driver's lap on the Rookie Loop: "
                      f"{braking_lap('rookie-loop')[0]:.2f} s")  # fmt: skip
            for seed in arguments.seeds:
                minutes, best, model_best = time_to_qualify(
                    owner, seed, arguments.limit, fast=arguments.fast,
                    workers=(arguments.workers or [1])[0],
                    lap_after=arguments.lap_after, steering=arguments.steering,
                    speed=tuple(arguments.speed), under=arguments.under,
                    algorithm=arguments.algorithm,
                    hyperparameters=dict(arguments.hyperparameter), reward=arguments.reward,
                )  # fmt: skip
                shown = f"{minutes:.1f}" if minutes is not None else f"> {arguments.limit:g}"
                if arguments.fast and arguments.under:
                    shown += f"; its best lap: {best:.2f} s" if best else ""
                elif arguments.fast:
                    shown += (
                        f"; best lap after {arguments.lap_after:g} min: {lap_words(best)}; "
                        f"the model's (its best checkpoint): {lap_words(model_best)}"
                    )
                print(f"seed {seed}: {shown}", flush=True)
        else:
            print("Training throughput, DeepRacer's defaults (PPO, camera, Rookie Loop):")
            for workers in arguments.workers or [1, 2]:
                throughput(owner, workers, arguments.minutes)


if __name__ == "__main__":
    main()
