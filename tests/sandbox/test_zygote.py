"""The zygote that forks a worker's sandbox children (``sandbox.zygote``, ``sandbox.spawner``):
children as a fresh interpreter's would be, a zygote that holds nothing of the worker's, and
one that ends with its worker or, once dead, is replaced."""

import os
import signal
import subprocess
import sys
import time

import pytest

from sandbox import CHILD_ENVIRONMENT, Sandbox, SandboxFailure
from sandbox.spawner import Zygote
from tests.helpers.sandbox import alive, outcome, reward


@pytest.fixture
def zygote():
    zygote = Zygote(CHILD_ENVIRONMENT)
    yield zygote
    zygote.stop()


def test_each_child_draws_its_own_random_numbers_as_a_fresh_interpreter_would():
    source = "import numpy\n" + reward("return numpy.random.random()")
    assert len({outcome(source) for _ in range(3)}) == 3


def test_the_zygote_holds_none_of_the_workers_environment(zygote, monkeypatch):
    monkeypatch.setenv("PITLANE_SECRET_KEY", "not for racers")
    child = zygote.spawn()
    with open(f"/proc/{zygote._process.pid}/environ", "rb") as environ:
        assert b"not for racers" not in environ.read()
    child.stdin.close()  # the child reads no start request and exits
    assert child.wait(10) == 0


def test_a_child_killed_by_its_worker_says_so_and_a_running_one_polls_none(zygote):
    child = zygote.spawn()
    assert child.poll() is None
    with pytest.raises(subprocess.TimeoutExpired):
        child.wait(0.1)
    child.kill()
    assert child.wait(10) == -signal.SIGKILL
    child.kill()  # reaped: nothing to signal, and nothing else signalled
    assert child.poll() == -signal.SIGKILL


def test_a_dead_zygote_takes_its_children_and_the_next_start_forks_from_a_new_one(zygote):
    child = zygote.spawn()
    first = zygote._process.pid
    os.kill(first, signal.SIGKILL)
    assert child.wait(10) == -signal.SIGKILL  # the child dies with its parent
    with Sandbox() as sandbox:  # the package's own zygote is untouched
        sandbox.load(reward("return 2.0"))
        assert sandbox.call({}) == 2.0
    again = zygote.spawn()
    assert zygote._process.pid != first
    again.stdin.close()
    assert again.wait(10) == 0


FORKED_WORKER = """
import os, time
import sandbox
from tests.helpers.sandbox import reward

def use(who):
    with sandbox.Sandbox() as box:
        box.load(reward("return 3.0"))
        print(who, box.call({}), sandbox._zygote()._process.pid, os.getpid(), flush=True)

use("parent")
read, write = os.pipe()
for uses in (True, False):  # as a Celery pool forks its processes, which live on
    if os.fork() == 0:
        if uses:
            use("child")
        else:
            print("idle", 0, 0, os.getpid(), flush=True)
        os.close(write)
        time.sleep(60)
        os._exit(0)
os.close(write)
os.read(read, 1)  # both forked processes have said who they are
use("parent")
os._exit(0)  # gone without its exit handlers, as a worker killed outright
"""


def test_a_forked_worker_starts_its_own_zygote_and_its_parents_ends_with_the_parent():
    worker = subprocess.Popen(
        [sys.executable, "-c", FORKED_WORKER], stdout=subprocess.PIPE, text=True, cwd=os.getcwd()
    )
    try:
        lines = {}
        for _ in range(4):
            who, value, zygote, pid = worker.stdout.readline().split()
            lines.setdefault(who, []).append((value, int(zygote), int(pid)))
        worker.wait(60)
    finally:
        worker.kill()
    forked = [pid for who in ("child", "idle") for _, _, pid in lines[who]]
    try:
        assert [value for value, _, _ in lines["parent"] + lines["child"]] == ["3.0"] * 3
        ((_, parents, _), _) = lines["parent"]
        ((_, childs, _),) = lines["child"]
        assert parents != childs
        deadline = time.monotonic() + 10
        while time.monotonic() < deadline and alive(parents):
            time.sleep(0.1)
        assert not alive(parents), "the parent's zygote outlived it"
        assert alive(childs)  # the forked process's, which lives on
    finally:
        for pid in forked:
            os.kill(pid, signal.SIGKILL)


@pytest.mark.parametrize("python", ["/bin/false", "/nowhere/python"], ids=["exits", "missing"])
def test_a_sandbox_whose_zygote_cannot_start_fails_in_words(monkeypatch, python):
    import sandbox as sandbox_package

    broken = Zygote(CHILD_ENVIRONMENT)
    monkeypatch.setattr(sandbox_package, "_zygote", lambda: broken)
    monkeypatch.setattr(sys, "executable", python)
    with pytest.raises(SandboxFailure) as failed:
        Sandbox().start()
    assert failed.value.kind == "crashed"
    assert str(failed.value) == "The simulation's process could not start."
