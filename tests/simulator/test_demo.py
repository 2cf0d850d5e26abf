import re
import subprocess
import sys

import cv2
import pytest

from tests.services import ROOT


def demo(*arguments: str) -> subprocess.CompletedProcess:
    return subprocess.run(
        [sys.executable, "-m", "simulator", "demo", *arguments],
        cwd=ROOT,
        capture_output=True,
        text=True,
        timeout=120,
    )


def test_the_demo_drives_a_lap_and_writes_the_spectator_video(tmp_path):
    out = tmp_path / "demo.mp4"
    result = demo("--track", "rookie-loop", "--out", str(out))
    assert result.returncode == 0, result.stderr
    lap = re.search(
        r"^Rookie Loop \(counterclockwise, 17.59 m\): lap in (\d+\.\d{3}) s at 1.5 m/s; video in ",
        result.stdout,
    )
    assert lap, result.stdout
    assert "slid" not in result.stdout  # 1.5 m/s is well within the grip
    video = cv2.VideoCapture(str(out))
    assert video.get(cv2.CAP_PROP_FRAME_WIDTH) == 640
    assert video.get(cv2.CAP_PROP_FRAME_HEIGHT) == 480
    # The start, then a frame for each step of the lap, at 15 frames/s.
    assert video.get(cv2.CAP_PROP_FRAME_COUNT) == 1 + round(float(lap[1]) * 15)
    ok, frame = video.read()
    assert ok and frame.std() > 20  # a picture, not a blank
    video.release()


@pytest.mark.slow
def test_the_demo_shows_a_hairpin_taken_too_fast_and_the_braking_that_takes_it(tmp_path):
    too_fast = demo("--track", "hairpin-alley", "--speed", "3", "--out", str(tmp_path / "a.mp4"))
    assert too_fast.returncode == 0, too_fast.stderr
    assert re.search(r"at 3.0 m/s; slid for \d+\.\d s, left the track \d+ times", too_fast.stdout)
    braking = demo(
        "--track", "hairpin-alley", "--speed", "3", "--braking", "--out", str(tmp_path / "b.mp4")
    )
    assert braking.returncode == 0, braking.stderr
    assert "braking for corners, up to 3.0 m/s" in braking.stdout
    assert "left the track" not in braking.stdout


def test_the_demo_names_an_unknown_track():
    result = subprocess.run(
        [sys.executable, "-m", "simulator", "demo", "--track", "monza"],
        cwd=ROOT,
        capture_output=True,
        text=True,
        timeout=60,
    )
    assert result.returncode == 2
    assert "No track named 'monza'" in result.stderr
    assert "Traceback" not in result.stderr
