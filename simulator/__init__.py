"""Pitlane's simulator: tracks, the car, its sensors and the DeepRacer-compatible environment.

Pure Python: this package never imports Django; the apps call into it.
"""
