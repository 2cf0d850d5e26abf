import subprocess
import sys

import cv2

from tests.services import ROOT


def test_the_demo_drives_a_lap_and_writes_the_spectator_video(tmp_path):
    out = tmp_path / "demo.mp4"
    result = subprocess.run(
        [sys.executable, "-m", "simulator", "demo", "--track", "rookie-loop", "--out", str(out)],
        cwd=ROOT, capture_output=True, text=True, timeout=120,
    )  # fmt: skip
    assert result.returncode == 0, result.stderr
    assert "Rookie Loop (counterclockwise, 17.59 m): lap in 12.000 s at 1.5 m/s" in result.stdout
    video = cv2.VideoCapture(str(out))
    assert video.get(cv2.CAP_PROP_FRAME_WIDTH) == 640
    assert video.get(cv2.CAP_PROP_FRAME_HEIGHT) == 480
    assert video.get(cv2.CAP_PROP_FRAME_COUNT) == 181  # the start and 12 s at 15 frames/s
    ok, frame = video.read()
    assert ok and frame.std() > 20  # a picture, not a blank
    video.release()


def test_the_demo_names_an_unknown_track():
    result = subprocess.run(
        [sys.executable, "-m", "simulator", "demo", "--track", "monza"],
        cwd=ROOT, capture_output=True, text=True, timeout=60,
    )  # fmt: skip
    assert result.returncode == 2
    assert "No track named 'monza'" in result.stderr
    assert "Traceback" not in result.stderr
