"""What `make run` starts on a machine, chosen from its cores and free memory (issue 56): as
many jobs train at once as the memory holds, and each variable an operator sets wins."""

from console.sizing import CARS, MAX_TRAINERS, GiB, machine_sizing, memory_available

NOTHING_SET: dict[str, str] = {}


def test_the_club_box_trains_six_racers_at_once():
    sizing = machine_sizing(cores=2, available=23 * GiB, environ=NOTHING_SET)
    assert sizing.trainers >= 6
    assert sizing.trainers <= MAX_TRAINERS
    assert sizing.simulations >= sizing.trainers + 2  # a rollout worker each, and evaluations
    assert sizing.cars == CARS
    assert sizing.trainer_threads == 2  # the most: a job alone learns on both (share_cores)


def test_a_tiny_machine_still_trains_one_job_with_fewer_cars():
    sizing = machine_sizing(cores=1, available=2 * GiB, environ=NOTHING_SET)
    assert (sizing.trainers, sizing.simulations, sizing.trainer_threads) == (1, 3, 1)
    assert 1 <= sizing.cars < CARS


def test_the_memory_bounds_the_trainers_before_the_cores_do():
    assert machine_sizing(cores=16, available=6 * GiB, environ=NOTHING_SET).trainers == 2
    assert machine_sizing(cores=16, available=500 * GiB, environ=NOTHING_SET).trainers == 8
    big = machine_sizing(cores=16, available=500 * GiB, environ=NOTHING_SET)
    assert (big.simulations, big.trainer_threads) == (16, 16)  # a process a core at least


def test_one_core_trains_at_most_four_jobs_however_much_memory_it_has():
    assert machine_sizing(cores=1, available=64 * GiB, environ=NOTHING_SET).trainers == 4


def test_each_variable_the_operator_sets_wins_and_what_depends_on_it_follows():
    environ = {"PITLANE_TRAINERS": "3", "PITLANE_CARS_PER_WORKER": "4"}
    sizing = machine_sizing(cores=4, available=2 * GiB, environ=environ)
    assert (sizing.trainers, sizing.cars) == (3, 4)
    assert (sizing.simulations, sizing.trainer_threads) == (5, 4)

    environ = {"PITLANE_WORKER_CONCURRENCY": "2", "PITLANE_TRAINER_THREADS": "6"}
    sizing = machine_sizing(cores=2, available=23 * GiB, environ=environ)
    assert (sizing.simulations, sizing.trainer_threads) == (2, 6)
    assert sizing.environment()["PITLANE_WORKER_CONCURRENCY"] == "2"


def test_make_run_says_what_it_chose_and_how_to_choose_otherwise():
    sizing = machine_sizing(cores=2, available=int(23.4 * GiB), environ={"PITLANE_TRAINERS": "6"})
    assert sizing.in_words() == (
        "This machine: 2 cores, 23.4 GiB of memory free. Training 6 jobs at once "
        "(PITLANE_TRAINERS), 8 simulation processes for their cars, evaluations and races "
        "(PITLANE_WORKER_CONCURRENCY), 8 cars a rollout worker (PITLANE_CARS_PER_WORKER); "
        "set any of them to choose otherwise."
    )


def test_the_free_memory_is_the_kernels_within_a_containers_limit(tmp_path):
    meminfo = tmp_path / "meminfo"
    meminfo.write_text("MemTotal:       24000000 kB\nMemAvailable:   20000000 kB\n")
    assert memory_available(meminfo, tmp_path / "no-cgroup") == 20000000 * 1024

    (tmp_path / "memory.max").write_text("4294967296\n")
    (tmp_path / "memory.current").write_text("1073741824\n")
    assert memory_available(meminfo, tmp_path) == 3 * GiB
    (tmp_path / "memory.max").write_text("max\n")
    assert memory_available(meminfo, tmp_path) == 20000000 * 1024


def test_one_of_each_is_said_in_the_singular():
    environ = {"PITLANE_WORKER_CONCURRENCY": "1", "PITLANE_CARS_PER_WORKER": "1"}
    words = machine_sizing(cores=1, available=2 * GiB, environ=environ).in_words()
    assert words.startswith("This machine: 1 core, 2.0 GiB of memory free. Training 1 job at")
    assert "1 simulation process for" in words
    assert "1 car a rollout worker" in words


def test_a_trainer_shares_the_cores_among_the_jobs_training_now_by_their_shares():
    from jobs.shares import cores_shared, niceness_for

    assert cores_shared(2, share=1, shares=1, most=2) == 2  # a job alone learns on both cores
    assert cores_shared(2, share=1, shares=6, most=2) == 1  # six on one each, never spinning
    assert cores_shared(16, share=1, shares=4, most=16) == 4
    assert cores_shared(16, share=1, shares=1, most=6) == 6  # PITLANE_TRAINER_THREADS
    # A racer staff gave 2 shares, beside two at 1: half the cores, and cars at full priority
    assert cores_shared(16, share=2, shares=4, most=16) == 8
    assert cores_shared(16, share=1, shares=4, most=16) == 4
    assert niceness_for(2, heaviest=2) == 0
    # Linux weighs niceness 3 at 526 against 1024 at 0 (kernel/sched/core.c): about half
    assert niceness_for(1, heaviest=2) == 3
    assert niceness_for(1, heaviest=4) == 6
    assert niceness_for(1, heaviest=8) == 9
