"""Training throughput and time to qualify: `python -m bench.bench_training [--qualify [--fast]]`.

Starts the whole console as `make run` does (its Redis, a Celery worker with enough processes for
a trainer and two rollout workers, the database in a scratch directory), creates models with all
of DeepRacer's defaults (the beginner track, the follow-the-centre-line reward function, PPO
defaults, the default discrete action space, the camera) and lets them train.

- Throughput: environment steps per second over 20 minutes of training (``--minutes``), policy
  updates included, with 1 and with 2 rollout workers, per iteration with where its time went,
  and the mean over the iterations whose training episodes completed a lap.
- With --update, the policy update alone, no console: milliseconds per environment step (SAC:
  per gradient step, one a step) on random camera frames, as Pitlane learns and with each change
  measured beside it (``UPDATE_VARIANTS``: stock layers, Adam not fused, SB3's minibatches
  copied one by one, bf16 features, channels-last tensors, torch.compile), on one thread and on
  all; ``--algorithm sac`` for SAC; ``--device cuda`` on a GPU, where torch.compile's
  reduce-overhead mode, PPO's eager minibatch step (the trainer replays a CUDA graph of it there,
  rl.graphed) and a CUDA graph of SAC's gradient step are measured too. A GPU
  session runs, each a minute or two on an H100:
  `python -m bench.bench_training --update --device cuda --steps 5000` and
  `python -m bench.bench_training --update --device cuda --algorithm sac --steps 2000`.
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
  said), as a racer's model may. ``--policy child`` keeps each rollout's policy in its sandbox
  child rather than the machine's policy server (``PITLANE_ROLLOUT_DEVICE``).
"""

from __future__ import annotations

import argparse
import os
import time

from bench.stack import add_policy_option, running_console
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
# The reward editor's example "Follow the racing line", with the bench track's line pasted in.
LINE = "line"
LINE_WAIT = 300  # [s] for a worker to compute a line with a margin


def reward_source(reward: str, track: str, margin_cm: int = 0) -> str:
    """The reward function ``reward`` names (``REWARDS`` or ``LINE``), for ``track``: with
    ``LINE``, the reward editor's example with ``track``'s line (counter-clockwise, ``margin_cm``
    inside the borders: the track page's choice) pasted over the one it holds, as a racer pastes
    the track page's copy. A line with a margin is computed by a worker, as for the page."""
    if reward != LINE:
        return REWARDS[reward]
    from training.models import Track, TrackLine
    from training.rewards import example_source
    from training.track_lines import track_line, with_racing_line

    track_row = Track.objects.get(name=track)
    deadline = time.monotonic() + LINE_WAIT
    while True:
        shown = track_line(track=track_row, direction="counterclockwise", margin_cm=margin_cm)
        if shown.status != TrackLine.Status.COMPUTING or time.monotonic() > deadline:
            break
        time.sleep(1)
    if shown.line is None:
        raise SystemExit(
            f"{track}'s racing line {margin_cm} cm in is not ready ({shown.status}"
            f"{': ' + shown.message if shown.message else ''}); without a margin: "
            "python -m simulator.racing_line"
        )
    return with_racing_line(example_source("follow_racing_line"), shown)


def bench_racer(name: str = "bench"):
    """A benchmark's racer, with a quota no benchmark reaches."""
    from django.contrib.auth.models import User

    from training.models import Quota

    owner = User.objects.create_user(name, password="bench-password-1")  # noqa: S106
    Quota.objects.create(racer=owner, max_models=1_000, max_minutes_per_month=1_000_000)
    return owner


def default_model(
    owner,
    name: str,
    *,
    workers: int = 1,
    seed: int = 0,
    fast: bool = False,
    steering: float = 30,
    speed: tuple[float, float] = FAST_SPEED,
    algorithm: str = PPO,
    hyperparameters: dict | None = None,
    reward: str = "road-ahead",
    randomise: bool = False,
    track: str = "rookie-loop",
    best_by: str = "progress",
    evaluation_trials: int = 5,
    line_margin: int = 0,
):
    """A model with DeepRacer's defaults on ``track`` (the Rookie Loop); ``hyperparameters``: the
    racer's own values of some (DeepRacer's names), over the algorithm's defaults; with ``fast``,
    ``reward`` names the reward function (``REWARDS``); ``randomise``: trained with domain
    randomisation; ``best_by``: how its training picks the best checkpoint (DeepRacer's
    BEST_MODEL_METRIC) over ``evaluation_trials`` episodes a checkpoint (its MIN_EVAL_TRIALS);
    ``line_margin``: [cm] with ``LINE``, the pasted line's margin."""
    from rl.hyperparameters import defaults
    from training.rewards import EXAMPLES
    from training.services import model_create

    settings = {
        "name": name,
        "track": track,
        "reward_function": EXAMPLES[0].source,
        "workers": workers,
        "seed": seed,
        "max_minutes": 1440,
        "domain_randomisation": randomise,
        "best_checkpoint_by": best_by,
        "evaluation_trials": evaluation_trials,
    }
    if fast:
        actions = {
            "steering_angle": {"low": -steering, "high": steering},
            "speed": {"low": speed[0], "high": speed[1]},
        }
        settings.update(
            action_space=actions,
            reward_function=reward_source(reward, track, line_margin),
            algorithm=algorithm,
        )
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
    print(
        "  iter  steps  wall s  steps/s  lap  " + "  ".join(f"{p:>8}" for p in PHASES) + "  eval s"
    )
    for row in rows:
        split = "  ".join(f"{row.time_split.get(p, 0.0):8.1f}" for p in PHASES)
        evaluation = f"{row.evaluation_seconds:6.1f}" if row.evaluation_seconds else "     —"
        print(
            f"  {row.number:4d}  {row.steps:5d}  {row.wall_seconds:6.1f}  "
            f"{row.steps / row.wall_seconds:7.1f}  {'yes' if row.best_lap_time else ' no'}  "
            f"{split}  {evaluation}"
        )

    def rate(chosen: list) -> str:
        wall = sum(row.wall_seconds for row in chosen)
        return f"{sum(row.steps for row in chosen) / wall:.1f} steps/s" if wall else "—"

    lapping = [row for row in rows if row.best_lap_time]
    print(
        f"  mean: {rate(rows)}; over the {len(lapping)} iterations that lapped: {rate(lapping)}",
        flush=True,
    )


def _update_spaces(algorithm: str):
    """The camera's observation space and DeepRacer's default action space for ``algorithm``
    (discrete for PPO; SAC's continuous, steering -30..30 degrees, speed 1..2 m/s)."""
    import gymnasium

    import simulator

    actions = {"steering_angle": {"low": -30, "high": 30}, "speed": {"low": 1, "high": 2}}
    settings = {"action_space": actions} if algorithm == SAC else {}
    env = gymnasium.make(simulator.ENV_ID, track="rookie-loop", **settings)
    env.close()
    return env.observation_space, env.action_space


def _update_episodes(spaces, steps: int, per_episode: int = 100) -> list:
    """``steps`` of random camera frames and actions, in episodes of ``per_episode``."""
    import numpy as np

    from rl.experience import Episode

    rng = np.random.default_rng(0)
    per_episode = min(per_episode, steps)
    frames = {
        name: rng.integers(0, 256, (per_episode + 1, *space.shape), dtype=np.uint8)
        for name, space in spaces[0].spaces.items()
    }
    action_space = spaces[1]

    def actions():
        if hasattr(action_space, "n"):
            return rng.integers(0, action_space.n, per_episode)
        low, high = action_space.low, action_space.high
        return rng.uniform(low, high, (per_episode, *low.shape)).astype(np.float32)

    def episode() -> Episode:
        return Episode(
            worker=0,
            version=0,
            observations=frames,
            actions=actions(),
            rewards=rng.random(per_episode, dtype=np.float32),
            values=rng.random(per_episode, dtype=np.float32),
            log_probs=np.full(per_episode, -2.3, np.float32),
            terminated=True,
            final_value=0.0,
            progress=10.0,
            status="off_track",
            lap_time=None,
            trace=[],
        )

    return [episode() for _ in range(max(1, steps // per_episode))]


def _stock_layers(built) -> None:
    from torch import nn

    from rl import networks

    policy = built.model.policy
    for module in policy.modules():
        if isinstance(module, networks.CameraConv2d):
            module.__class__ = nn.Conv2d
    _adam(built, fused=False)


def _adam(built, **options) -> None:
    """PPO's Adam rebuilt with ``options`` (unfused by default)."""
    import torch

    policy = built.model.policy
    learning_rate = policy.optimizer.param_groups[0]["lr"]
    policy.optimizer = torch.optim.Adam(policy.parameters(), lr=learning_rate, eps=1e-5, **options)


def _compiled(mode: str | None):
    def change(built) -> None:
        import torch

        policy = built.model.policy
        for name in ("pi_features_extractor", "vf_features_extractor"):
            setattr(policy, name, torch.compile(getattr(policy, name), mode=mode))

    return change


def _channels_last(built) -> None:
    import torch

    built.model.policy.to(memory_format=torch.channels_last)


def _sb3_minibatches(built) -> None:
    from rl.ppo import sb3_minibatches

    built.model._minibatches = lambda: sb3_minibatches(built.model)


def _bf16(built) -> None:
    import torch

    built.precision = torch.bfloat16


def _sb3_sac_step(built) -> None:
    from stable_baselines3 import SAC as SB3SAC

    model = built.model
    model.replay_buffer.sample = lambda size, env=None: model.replay.sample(size)
    model.train = lambda gradient_steps, batch_size: SB3SAC.train(model, gradient_steps, batch_size)


def _captured(step, optimizers: list):
    """``step`` (a whole gradient step on fixed input tensors) as a CUDA graph's replay, its
    gradients made in the graph's memory (set to None before the step, so never accumulated)."""
    from rl.graphed import cuda_capture

    def zeroed() -> None:
        for optimizer in optimizers:
            optimizer.zero_grad(set_to_none=True)
        step()

    return cuda_capture(zeroed)


def _capturable(module, **options) -> None:
    """``module``'s Adam rebuilt fused and capturable (its step state on the GPU), as a CUDA
    graph needs; a distribution's argument checks (a wait on the GPU each) left out: for every
    distribution the process builds after, not the module's alone (torch has only a default
    for all), so ``update_speed`` puts the default back after the variant."""
    import torch

    learning_rate = module.optimizer.param_groups[0]["lr"]
    module.optimizer = torch.optim.Adam(
        module.parameters(), lr=learning_rate, fused=True, capturable=True, **options
    )
    torch.distributions.Distribution.set_default_validate_args(False)


def _sac_cuda_graph(built) -> None:
    """SAC's whole gradient step (critics, actor, target critics; the actor's draws from the
    default generator, which CUDA graphs replay anew) captured once as a CUDA graph and
    replayed for each step, each sampled batch copied into the graph's."""
    import torch

    from rl.graphed import batch_tensors

    model = built.model
    _capturable(model.actor)
    _capturable(model.critic)
    captured = {}

    def train(gradient_steps: int, batch_size: int) -> None:
        model.policy.set_training_mode(True)
        if "graph" not in captured:
            captured["batch"] = model.replay.sample(batch_size)
            step = lambda: model.gradient_step(captured["batch"])  # noqa: E731
            captured["graph"] = _captured(step, [model.actor.optimizer, model.critic.optimizer])
        for _ in range(gradient_steps):
            fresh = batch_tensors(model.replay.sample(batch_size))
            torch._foreach_copy_(batch_tensors(captured["batch"]), fresh)
            captured["graph"]()

    model.train = train


# name: (the change to a Pitlane learner, CUDA only); what Pitlane adopts is "Pitlane"
UPDATE_VARIANTS = {
    PPO: {
        "stock layers, Adam not fused": (_stock_layers, False),
        "Pitlane": (lambda built: None, False),
        "Pitlane, bf16 features": (_bf16, False),
        "Pitlane, Adam not fused": (lambda built: _adam(built), False),
        "Pitlane, SB3's minibatches (copied each)": (_sb3_minibatches, False),
        "Pitlane, channels last": (_channels_last, False),
        "Pitlane, torch.compile": (_compiled(None), False),
        "Pitlane, torch.compile reduce-overhead": (_compiled("reduce-overhead"), True),
        "Pitlane, the eager minibatch step (no CUDA graph)": (lambda built: None, True),
    },
    SAC: {
        "SB3's gradient step": (_sb3_sac_step, False),
        "Pitlane": (lambda built: None, False),
        "Pitlane, bf16 features": (_bf16, False),
        "Pitlane, CUDA graph of the gradient step": (_sac_cuda_graph, True),
    },
}


def update_speed(steps: int = 2000, *, algorithm: str = PPO, device: str = "cpu") -> None:
    """[ms] an update takes per environment step with DeepRacer's defaults (3-layer CNN, camera;
    PPO: 10 epochs of minibatches of 64, SAC: a gradient step of 64 per step) on random camera
    frames, on ``device``: as Pitlane learns and with each change measured (``UPDATE_VARIANTS``),
    on one thread and on all (on a GPU, once)."""
    import torch

    from rl import hyperparameters, networks
    from rl.learner import Learner

    spaces = _update_spaces(algorithm)
    episodes = _update_episodes(spaces, steps)
    warm_up = _update_episodes(spaces, 8 if algorithm == SAC else 200, per_episode=8)
    counts = sorted({1, os.cpu_count() or 1}) if device == "cpu" else [torch.get_num_threads()]
    print(
        f"{algorithm} update on {device}, DeepRacer's defaults, {steps} steps "
        f"[ms per step; warm-up s]:"
    )
    for threads in counts:
        torch.set_num_threads(threads)
        for name, (change, cuda_only) in UPDATE_VARIANTS[algorithm].items():
            if cuda_only and not device.startswith("cuda"):
                print(f"  {name}: needs --device cuda", flush=True)
                continue
            validating = torch.distributions.Distribution._validate_args  # a capture's to undo
            built = Learner(
                algorithm=algorithm,
                hyperparameters=hyperparameters.defaults(algorithm),
                architecture=networks.SHALLOW,
                observation_space=spaces[0],
                action_space=spaces[1],
                device=device,
            )
            if name != "Pitlane" and algorithm == PPO:  # each change to the eager step
                built.model.graphed = None
                torch.distributions.Distribution.set_default_validate_args(validating)
            change(built)
            started = time.perf_counter()
            built.learn(warm_up)  # (and compile, capture)
            _synchronise(device)
            warmed = time.perf_counter() - started
            started = time.perf_counter()
            built.learn(episodes)
            _synchronise(device)
            took = (time.perf_counter() - started) / sum(e.steps for e in episodes) * 1000
            torch.distributions.Distribution.set_default_validate_args(validating)
            print(f"  {threads} thread(s), {name}: {took:.2f}; {warmed:.1f}", flush=True)


def _synchronise(device: str) -> None:
    import torch

    if device.startswith("cuda"):
        torch.cuda.synchronize()


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
    learner = Learner.for_model(model, env)
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


def other_best_words(job, best_by: str, driven: dict[int, tuple[bool, list[float]]]) -> str:
    """Which checkpoint the other of progress and lap time (``best_by``'s) would have made
    ``job``'s best, and its 3 laps as ``driven`` has them (they are driven alike every time)."""
    from jobs.checkpoints import best_iteration
    from training.models import BestCheckpointBy, Iteration

    other = (
        BestCheckpointBy.PROGRESS
        if best_by != BestCheckpointBy.PROGRESS
        else BestCheckpointBy.LAPTIME
    )
    row = best_iteration(rows=Iteration.objects.filter(job=job), metric=other)
    if row is None:
        return f"by {other}: no checkpoint evaluated"
    ok, laps = driven.get(row.number, (False, []))
    laps = laps_words(laps) if row.number in driven else "not driven"
    clean = "3" if ok else "not 3"
    return f"by {other} the best would be iteration {row.number}: {clean} clean laps: {laps}"


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
    track: str = "rookie-loop",
    best_by: str = "progress",
    evaluation_trials: int = 5,
    line_margin: int = 0,
) -> tuple[float | None, float | None, float | None, tuple[float, int] | None]:
    """(training minutes to qualify or None, with --fast the best lap of the first checkpoint
    after ``lap_after`` minutes and that of the model then, its best checkpoint, and the fastest
    lap of any checkpoint before with its iteration; a lap only where 3 were clean); a fast model
    trains on to ``lap_after`` once it qualifies, and also shows the checkpoint the other of
    progress and lap time would have made its best.
    With ``under``, qualifying takes 3 clean laps each under that many seconds; ``workers``: the
    model's rollout workers; ``best_by``: the model's BEST_MODEL_METRIC over
    ``evaluation_trials`` episodes a checkpoint; ``line_margin``: [cm]
    the pasted racing line's margin."""
    from training import artifacts
    from training.services import training_stop

    model = default_model(
        owner,
        f"qualify-{seed}{'-fast' if fast else ''}",
        seed=seed,
        fast=fast,
        steering=steering,
        speed=speed,
        algorithm=algorithm,
        hyperparameters=hyperparameters,
        reward=reward,
        workers=workers,
        track=track,
        best_by=best_by,
        evaluation_trials=evaluation_trials,
        line_margin=line_margin,
    )
    driven = {}  # iteration: (3 clean laps, the lap times) of each checkpoint driven
    qualified = fastest = None
    while True:
        job = job_of(model)
        minutes = job.training_seconds / 60
        number = artifacts.checkpoint_iteration(job.last_checkpoint or "")
        if number is not None and number not in driven and job.iterations > 0:
            ok, laps, spread_words = qualifies(model, job.last_checkpoint)
            driven[number] = ok, laps
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
            if ok and (fastest is None or min(laps) < fastest[0]):
                fastest = (min(laps), job.iterations)
            if qualified is not None and (not fast or under is not None):
                training_stop(job=job)  # the time to qualify (or to the lap time) is known
                return qualified, (min(laps) if fast else None), None, fastest
            if fast and minutes >= lap_after:
                training_stop(job=job)
                model_ok, model_laps, iteration = racers_model(model)
                print(
                    f"  seed {seed}: the model, its best checkpoint by {best_by} (iteration "
                    f"{iteration}): {'3' if model_ok else 'not 3'} clean laps: "
                    f"{laps_words(model_laps)}",
                    flush=True,
                )
                print(f"  seed {seed}: {other_best_words(job_of(model), best_by, driven)}")
                best_lap, model_lap = (
                    min(laps) if ok else None,
                    min(model_laps) if model_ok else None,
                )
                return qualified, best_lap, model_lap, fastest
        # With --fast the lap is the first checkpoint's after lap_after, which may land a whole
        # iteration after it: wait for it (up to LATE_CHECKPOINT more minutes).
        lapping = fast and under is None
        if minutes > (max(limit, lap_after + LATE_CHECKPOINT) if lapping else limit):
            training_stop(job=job)
            return qualified, None, None, fastest
        time.sleep(5)


def _setting(text: str) -> tuple[str, float]:
    name, _, value = text.partition("=")
    try:
        return name, float(value)
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r} is not NAME=NUMBER") from None


def racing_line_laps(track: str) -> tuple[float, float]:
    """(from a standing start, flying) [s]: the built-in ``track``'s stored racing line's laps,
    counter-clockwise, as the models here train on it."""
    from simulator import racing_line, tracks

    line = racing_line.stored_line(tracks.load(track).with_direction("counterclockwise"))
    if line is None:
        raise SystemExit(
            f"{track} has no current stored racing line: python -m simulator.racing_line"
        )
    return line.standing_lap_time, line.lap_time


def main() -> None:
    from rl.learner import PRECISIONS

    parser = argparse.ArgumentParser()
    parser.add_argument("--qualify", action="store_true", help="measure the time to qualify")
    parser.add_argument(
        "--update", action="store_true", help="time the policy update alone, without a console"
    )
    parser.add_argument(
        "--steps", type=int, default=2000, help="with --update, the steps learnt from"
    )
    parser.add_argument(
        "--device", default="cpu", help="with --update, where to learn: cpu, cuda (or cuda:N)"
    )
    parser.add_argument(
        "--precision",
        choices=PRECISIONS,
        default="fp32",
        help="the trainer's PITLANE_TRAINER_PRECISION, for the throughput and --qualify",
    )
    parser.add_argument(
        "--minutes",
        type=float,
        default=THROUGHPUT_MINUTES,
        help="[min] of training for the throughput",
    )
    parser.add_argument(
        "--workers",
        type=int,
        nargs="+",
        default=None,
        help="rollout workers: for throughput, each count in turn (default 1 and 2); with "
        "--qualify, the model's (one count, default 1)",
    )
    add_policy_option(parser)
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
        "--speed",
        type=float,
        nargs=2,
        default=FAST_SPEED,
        metavar=("LOW", "HIGH"),
        help="[m/s] with --fast, the speed range",
    )
    parser.add_argument(
        "--reward",
        choices=(*REWARDS, LINE),
        default="road-ahead",
        help="with --fast, the reward function: the road ahead's speed, that with steady hands, "
        "that with a steady heading too, or (line) the reward editor's 'Follow the racing line' "
        "with the track's line",
    )
    parser.add_argument(
        "--best-by",
        choices=("progress", "reward", "laptime"),
        default="progress",
        help="with --qualify, how the model's training picks its best checkpoint (DeepRacer's "
        "BEST_MODEL_METRIC, DeepRacer for Cloud's DR_TRAIN_BEST_MODEL_METRIC)",
    )
    parser.add_argument(
        "--evaluation-trials",
        type=int,
        choices=range(1, 21),
        default=5,
        metavar="N",
        help="with --qualify, the evaluation episodes (1-20) each checkpoint drives to pick the "
        "best (DeepRacer's MIN_EVAL_TRIALS, 5; DeepRacer for Cloud's DR_TRAIN_MIN_EVAL_TRIALS)",
    )
    parser.add_argument(
        "--line-margin",
        type=int,
        choices=range(21),
        default=0,
        metavar="CM",
        help="with --reward line, the pasted line kept this many cm (0-20) further inside the "
        "borders, as the track page offers; the laps are still set against the line without one",
    )
    parser.add_argument(
        "--under",
        type=float,
        default=None,
        help="[s] qualifying takes 3 clean laps each under this time",
    )
    parser.add_argument(
        "--algorithm",
        choices=(PPO, SAC),
        default=PPO,
        help="with --fast or --update, PPO (DeepRacer's default) or SAC",
    )
    parser.add_argument(
        "--hyperparameter",
        type=_setting,
        action="extend",
        nargs="+",
        default=[],
        metavar="NAME=VALUE",
        help="with --qualify, a racer's own value (DeepRacer's names)",
    )
    parser.add_argument(
        "--cars",
        type=int,
        default=None,
        help="the console's PITLANE_CARS_PER_WORKER: cars a rollout worker drives together "
        "(default: the console's, 8; 1 is how a worker drove before issue 43)",
    )
    parser.add_argument("--seeds", type=int, nargs="+", default=[0, 1, 2])
    parser.add_argument(
        "--track",
        default="rookie-loop",
        help="with --qualify, the built-in track trained on (counter-clockwise)",
    )
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
        update_speed(arguments.steps, algorithm=arguments.algorithm, device=arguments.device)
        return
    if arguments.cars is not None and not 1 <= arguments.cars <= 64:
        parser.error("--cars takes 1 to 64 (PITLANE_CARS_PER_WORKER's range)")
    console_settings = {
        "PITLANE_TRAINER_PRECISION": arguments.precision,
        "PITLANE_ROLLOUT_DEVICE": arguments.policy,
    }
    if arguments.cars is not None:
        console_settings["PITLANE_CARS_PER_WORKER"] = str(arguments.cars)
    with running_console(concurrency=3, settings=console_settings) as console:
        os.environ.update(console["env"])
        import django

        django.setup()
        from django.conf import settings as dj_settings

        owner = bench_racer()
        cars = arguments.cars or dj_settings.PITLANE_CARS_PER_WORKER
        where = "" if arguments.policy == "auto" else f"; PITLANE_ROLLOUT_DEVICE={arguments.policy}"
        print(f"Trainer precision {arguments.precision}; {cars} car(s) a rollout worker{where}")
        if arguments.qualify:
            under = f", each under {arguments.under:g} s" if arguments.under else ""
            print(f"Time to qualify (3 clean consecutive laps{under}), training minutes:")
            if arguments.fast:
                from bench.bench_simulator import braking_lap

                line = racing_line_laps(arguments.track)
                print(
                    f"On {arguments.track}: the braking driver's lap "
                    f"{braking_lap(arguments.track)[0]:.2f} s; the racing line's "
                    f"{line[0]:.2f} s from a standing start, {line[1]:.2f} s flying"
                )
            for seed in arguments.seeds:
                minutes, best, model_best, fastest = time_to_qualify(
                    owner,
                    seed,
                    arguments.limit,
                    fast=arguments.fast,
                    workers=(arguments.workers or [1])[0],
                    lap_after=arguments.lap_after,
                    steering=arguments.steering,
                    speed=tuple(arguments.speed),
                    under=arguments.under,
                    algorithm=arguments.algorithm,
                    hyperparameters=dict(arguments.hyperparameter),
                    reward=arguments.reward,
                    track=arguments.track,
                    best_by=arguments.best_by,
                    evaluation_trials=arguments.evaluation_trials,
                    line_margin=arguments.line_margin,
                )
                shown = f"{minutes:.1f}" if minutes is not None else f"> {arguments.limit:g}"
                if arguments.fast and arguments.under:
                    shown += f"; its best lap: {best:.2f} s" if best else ""
                elif arguments.fast:
                    shown += (
                        f"; best lap after {arguments.lap_after:g} min: {lap_words(best)}; "
                        f"the model's (its best checkpoint): {lap_words(model_best)}"
                    )
                    if model_best:  # its fastest of 3 laps, a flying one but where the first
                        shown += f", {model_best / line[1]:.3f} times the line's flying lap"
                    if fastest:  # what the newest checkpoint with the best progress is not
                        shown += (
                            f"; the fastest checkpoint's (iteration {fastest[1]}): "
                            f"{fastest[0]:.2f} s, {fastest[0] / line[1]:.3f} times the line's"
                        )
                print(f"seed {seed}: {shown}", flush=True)
        else:
            print("Training throughput, DeepRacer's defaults (PPO, camera, Rookie Loop):")
            for workers in arguments.workers or [1, 2]:
                throughput(owner, workers, arguments.minutes)


if __name__ == "__main__":
    main()
