import csv
import io
import itertools

import pytest

from simulator.trace import FIELDS, LOG_PREFIX, TraceWriter, log_line, to_csv
from tests.simulator.conftest import CONTINUOUS, drive, make

DEEPRACER_HEADER = (
    "episode,steps,X,Y,yaw,steer,throttle,action,reward,done,all_wheels_on_track,progress,"
    "closest_waypoint,track_len,tstamp,episode_status,pause_duration,obstacle_crash_counter,"
    "wall_clock"
)


def rows_from(**settings):
    """The prepare row and 30 steps' rows of an episode."""
    env = make(track="pitlane-oval", **settings)
    _, info = env.reset(seed=0)
    rows = [info["trace"]] + [info["trace"] for info in drive(env, steps=30)]
    env.close()
    return rows


def test_the_trace_has_deepracers_19_fields_in_order():
    assert ",".join(FIELDS) == DEEPRACER_HEADER


def test_a_log_line_is_prefixed_and_has_19_fields():
    row = rows_from()[-1]
    line = log_line(row)
    assert line.startswith(LOG_PREFIX)
    fields = line.removeprefix(LOG_PREFIX).split(",")
    assert len(fields) == 19
    assert fields[0] == "0" and fields[1] == "31"  # an integer, as SIM_TRACE_LOG's %d
    assert fields[9] == "False" and fields[15] == "in_progress"
    assert float(fields[18]) > 1.7e9  # stamped with the wall clock when written


def test_the_csv_reads_back_with_its_header():
    rows = rows_from()
    table = list(csv.DictReader(io.StringIO(to_csv(rows))))
    assert list(table[0]) == list(FIELDS)
    assert len(table) == 31
    assert [r["steps"] for r in table] == [f"{n}.0" for n in range(1, 32)]  # floats, as DeepRacer
    assert float(table[-1]["progress"]) > float(table[0]["progress"])
    assert float(table[-1]["tstamp"]) - float(table[0]["tstamp"]) == pytest.approx(2.0)


def test_an_episode_begins_with_deepracers_prepare_row():
    prepare, first = rows_from()[:2]
    assert (prepare.steps, prepare.episode_status, prepare.reward, prepare.done) == (
        1.0,
        "prepare",
        0.0,
        False,
    )
    assert prepare.all_wheels_on_track is True and prepare.progress == 0.0
    assert (first.steps, first.episode_status) == (2.0, "in_progress")


def test_the_timestamp_runs_on_through_resets_and_never_backwards():
    env = make(track="pitlane-oval")
    rows = []
    for seed in (0, None, None):
        _, info = env.reset(seed=seed)
        rows += [info["trace"]] + [info["trace"] for info in drive(env, steps=10)]
    env.close()
    stamps = [row.tstamp for row in rows]
    assert all(b > a for a, b in itertools.pairwise(stamps))
    assert [row.episode for row in rows if row.episode_status == "prepare"] == [0, 1, 2]
    # Each episode lasts its steps after the prepare row: the time deepracer-utils sums.
    assert rows[10].tstamp - rows[0].tstamp == pytest.approx(10 / 15)


def test_a_continuous_action_is_written_as_steer_and_speed():
    row = rows_from(action_space=CONTINUOUS)[-1]
    steer, speed = row.action.strip("[]").split()
    assert float(speed) == 1.5
    assert abs(float(steer)) <= 30


def test_an_iteration_file_goes_where_deepracer_utils_looks(tmp_path):
    rows = rows_from()
    with TraceWriter.for_iteration(tmp_path / "training-simtrace", 3) as writer:
        for row in rows:
            writer.write(row)
    text = (tmp_path / "training-simtrace" / "3-iteration.csv").read_text()
    assert text.splitlines()[0] == DEEPRACER_HEADER
    assert len(text.splitlines()) == 32
