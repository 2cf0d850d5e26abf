"""The web tier stays light: a Daphne process never simulates nor learns, so starting one loads
neither the simulator's physics and pictures nor the learner's tensors."""

import json
import os
import subprocess
import sys

from django.conf import settings

HEAVY = ("torch", "pybullet", "cv2", "stable_baselines3", "onnx", "onnxruntime")

START_WEB_PROCESS = """
import json, sys
import console.asgi  # what Daphne loads: Django set up, the HTTP and websocket routes
from django.contrib import admin
from django.urls import get_resolver

def walk(patterns):  # every view module the URLs name, as the first requests would load them
    for pattern in patterns:
        walk(getattr(pattern, "url_patterns", []))

walk(get_resolver().url_patterns)
admin.site.get_urls()
print(json.dumps(sorted(name for name in sys.modules if name.split(".")[0] in %r)))
"""


def test_starting_a_web_process_imports_no_torch_physics_or_opencv():
    environment = {**os.environ, "DJANGO_SETTINGS_MODULE": "console.settings.test"}
    started = subprocess.run(
        [sys.executable, "-c", START_WEB_PROCESS % (HEAVY,)],
        cwd=settings.BASE_DIR,
        env=environment,
        capture_output=True,
        text=True,
        timeout=120,
        check=False,
    )
    assert started.returncode == 0, started.stderr
    loaded = json.loads(started.stdout.strip().splitlines()[-1])
    assert loaded == [], f"a web process imported {sorted({m.split('.')[0] for m in loaded})}"


def test_a_sandbox_child_that_only_validates_loads_no_torch():
    # Every validation starts a child: PyTorch (about a second) comes only with a policy.
    started = subprocess.run(
        [
            sys.executable,
            "-c",
            "import sys, sandbox.child; "
            "print(sorted({'torch', 'stable_baselines3'} & set(sys.modules)))",
        ],
        cwd=settings.BASE_DIR,
        capture_output=True,
        text=True,
        timeout=120,
        check=False,
    )
    assert started.returncode == 0, started.stderr
    assert started.stdout.strip() == "[]"
