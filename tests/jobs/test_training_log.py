"""The training log: the trainer's messages, the simulation workers' and what the reward function
printed (a bounded share of it, so that a print flood costs neither memory nor the database),
each line with its source; the model page filters it, and the whole log downloads as text."""

import pytest
from django.urls import reverse

from common.redis_client import redis_client
from jobs import rollouts
from rl.experience import JobChannel, LogEntry
from sandbox import LOG_KEEP, Sandbox
from sandbox.reward import MAX_LOG
from tests.helpers.models import ready_model
from tests.helpers.sandbox import PARAMS, reward
from training.models import JobLogLine, TrainingJob

FLOOD = """\
for i in range(20_000):
    print("line", i)
print("x" * 10_000_000)
return 1.0
"""


def test_a_print_flood_keeps_the_first_lines_and_counts_the_rest():
    with Sandbox(call_timeout=30) as sandbox:  # printing takes time on a busy machine
        sandbox.load(reward(FLOOD))
        assert sandbox.call(PARAMS) == 1.0
        lines, dropped = sandbox.take_logs()
    assert lines[:2] == ["line 0", "line 1"] and len(lines) == MAX_LOG
    assert dropped == 20_001 - MAX_LOG
    assert sandbox.take_logs() == ([], 0)


class Printing:
    """A stand-in for a sandbox that printed ``count`` lines since the last take."""

    def __init__(self) -> None:
        self.count, self.dropped = 0, 0

    def take_logs(self) -> tuple[list[str], int]:
        taken = ([f"progress {i}" for i in range(self.count)], self.dropped)
        self.count, self.dropped = 0, 0
        return taken


def test_a_worker_keeps_a_share_of_each_iterations_prints_and_says_how_many_more_there_were():
    sandbox, printed = Printing(), rollouts.Printed()
    sandbox.count = 15
    first = printed.take(sandbox, 1)
    sandbox.count, sandbox.dropped = 15, 1000  # its sandbox kept 15 and counted 1,000 more
    second = printed.take(sandbox, 1)
    assert [entry.source for entry in first + second] == ["reward"] * rollouts.PRINTED_LINES
    sandbox.count = 3
    third = printed.take(sandbox, 2)  # the next iteration: a note for the last, then its lines
    assert third[0] == LogEntry("reward", "… 1,010 more lines printed in iteration 1 not kept")
    assert [entry.text for entry in third[1:]] == ["progress 0", "progress 1", "progress 2"]
    assert printed.close() == []


def test_with_several_workers_each_line_says_which_printed_it():
    sandbox, printed = Printing(), rollouts.Printed("Simulation worker 2")
    sandbox.count = 25
    entries = printed.take(sandbox, 4) + printed.close()
    assert entries[0].text == "Simulation worker 2: progress 0"
    assert (
        entries[-1].text == "… 5 more lines printed by simulation worker 2 in iteration 4 not kept"
    )


@pytest.mark.slow
def test_the_job_channel_carries_only_worker_and_reward_lines():
    channel = JobChannel(redis_client(), job_id=987_654)
    channel.client.delete(channel.log)
    channel.push_log([LogEntry("reward", "x" * 2000), LogEntry("worker", "Simulation worker 1.")])
    channel.client.rpush(channel.log, '["trainer", "info", "forged"]', "not json")
    entries = channel.pop_log()
    assert [(e.source, len(e.text)) for e in entries] == [("reward", 500), ("worker", 20)]


@pytest.fixture
def logged(alice, tracks) -> TrainingJob:
    model = ready_model(alice, name="logged")
    job = TrainingJob.objects.get(model=model)
    for source, text in [
        ("trainer", "Training started: PPO, 1 simulation worker, learning on the CPU."),
        ("worker", "Simulation worker 1 is driving Pitlane Oval."),
        ("reward", "progress 12.5"),
        ("trainer", "Iteration 1: 5 episodes, 300 steps, average progress 12.5%, learnt in 2 s."),
    ]:
        JobLogLine.objects.create(job=job, source=source, text=text)
    return job


@pytest.mark.django_db
def test_the_log_panel_shows_each_lines_source_and_filters_by_it(client, alice, logged):
    client.force_login(alice)
    url = reverse("training:model-detail", args=[logged.model_id])
    page = client.get(url).text
    assert page.count('data-source="') == 4
    assert '<span class="log-source">Reward function</span> progress 12.5' in page
    only_prints = client.get(url, {"log": "reward"}).text
    assert only_prints.count('data-source="') == 1 and 'data-source="reward"' in only_prints
    assert client.get(url, {"log": "nonsense"}).text.count('data-source="') == 4


@pytest.mark.django_db
def test_the_whole_log_downloads_as_text_for_its_owner_only(client, alice, bob, logged):
    url = reverse("training:model-log", args=[logged.model_id])
    client.force_login(bob)
    assert client.get(url).status_code == 404
    client.force_login(alice)
    response = client.get(url)
    assert response.status_code == 200
    assert response["Content-Type"] == "text/plain; charset=utf-8"
    assert 'filename="logged-training-log.txt"' in response["Content-Disposition"]
    text = b"".join(response.streaming_content).decode()
    lines = text.splitlines()
    assert lines[0].startswith("Training log of logged")
    assert lines[1].endswith(
        "[Trainer] Training started: PPO, 1 simulation worker, learning on the CPU."
    )
    assert lines[2].endswith("[Simulation worker] Simulation worker 1 is driving Pitlane Oval.")
    assert lines[3].endswith("[Reward function] progress 12.5")
    assert len(lines) == 5
    assert LOG_KEEP >= MAX_LOG


@pytest.mark.django_db
def test_the_log_panel_alone_is_its_owners_lines_in_time_order(client, alice, bob, logged):
    url = reverse("training:model-log-panel", args=[logged.model_id])
    client.force_login(bob)
    assert client.get(url).status_code == 404
    client.force_login(alice)
    panel = client.get(url).text
    assert "<html" not in panel and "data-log" in panel
    said = [
        panel.index(text)
        for text in (
            "Training started",
            "driving Pitlane",
            "progress 12.5",
            "Iteration 1: 5 episodes",
        )
    ]
    assert said == sorted(said)
    only_prints = client.get(url, {"log": "reward"}).text
    assert only_prints.count('data-source="') == 1 and 'data-source="reward"' in only_prints
    page = client.get(reverse("training:model-detail", args=[logged.model_id])).text
    assert f'data-log-url="{url}"' in page
