import random


def reward_function(params):
    # A little noise, for exploration. (Racers do this; it is allowed.)
    base = 1.0 if params["all_wheels_on_track"] else 0.0
    return base + random.uniform(0.0, 0.05)
