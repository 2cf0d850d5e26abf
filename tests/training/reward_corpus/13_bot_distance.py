import numpy as np


def reward_function(params):
    # Head-to-bot: keep a distance from the car ahead, measured along the track.
    reward = 1.0 if params["all_wheels_on_track"] else 1e-3
    if "objects_distance" in params and params["objects_distance"]:
        here = params["projection_distance"]
        length = params["track_length"]
        gaps = (np.array(params["objects_distance"]) - here) % length
        nearest = float(gaps.min())
        if nearest < 0.5:
            reward *= 0.3
        elif nearest < 1.0:
            reward *= 0.7
    return float(reward)
