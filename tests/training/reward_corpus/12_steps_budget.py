TOTAL_NUM_STEPS = 300


def reward_function(params):
    """DeepRacer's documented progress incentive: finish the lap within a step budget."""
    if not params["all_wheels_on_track"]:
        return 1e-3
    reward = 1.0
    if (params["steps"] % 100) == 0 and params["progress"] > (
        params["steps"] / TOTAL_NUM_STEPS
    ) * 100:
        reward += 10.0
    return float(reward)
