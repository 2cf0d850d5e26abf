import math

# The racing line of reInvent2019_track driven counter-clockwise, from Pitlane.
# [x, y, speed]: a point every 0.2 m from the start line; x and y in metres,
# as params["x"] and params["y"] read them; the speed in m/s the line is driven at.
# A flying lap takes 6.80 s; the first, from a standing start, 7.02 s.
RACING_LINE = [
    [-3.7981, -0.0361, 1.97],
    [-3.8138, -0.1978, 1.91],
    [-3.7970, -0.4006, 2.37],
    [-3.7611, -0.5759, 2.54],
    [-3.7042, -0.7564, 2.88],
    [-3.6332, -0.9315, 3.03],
    [-3.5513, -1.0941, 2.73],
    [-3.4617, -1.2375, 2.52],
    [-3.3665, -1.3608, 2.19],
    [-3.2706, -1.4606, 1.86],
    [-3.1855, -1.5279, 1.85],
    [-3.0979, -1.5852, 2.11],
    [-2.9909, -1.6515, 2.39],
    [-2.8285, -1.7333, 2.73],
    [-2.6323, -1.8228, 3.10],
    [-2.4203, -1.9070, 3.44],
    [-2.2051, -1.9762, 3.60],
    [-1.9975, -2.0309, 3.60],
    [-1.8093, -2.0744, 3.60],
    [-1.6482, -2.1099, 3.60],
    [-1.5093, -2.1424, 3.60],
    [-1.3801, -2.1776, 3.60],
    [-1.2266, -2.2256, 3.60],
    [-1.0386, -2.2901, 3.60],
    [-0.8212, -2.3702, 3.55],
    [-0.6063, -2.4432, 3.38],
    [-0.4170, -2.4939, 3.45],
    [-0.2429, -2.5332, 3.19],
    [-0.0788, -2.5604, 3.02],
    [0.0781, -2.5754, 2.79],
    [0.2286, -2.5805, 2.51],
    [0.3787, -2.5725, 2.75],
    [0.5279, -2.5527, 2.99],
    [0.6750, -2.5233, 3.16],
    [0.8110, -2.4880, 3.16],
    [0.9522, -2.4428, 3.27],
    [1.1173, -2.3821, 3.52],
    [1.2873, -2.3136, 3.30],
    [1.4564, -2.2337, 3.14],
    [1.6223, -2.1397, 3.37],
    [1.7834, -2.0337, 3.53],
    [1.9390, -1.9171, 3.60],
    [2.0883, -1.7909, 3.60],
    [2.2300, -1.6559, 3.58],
    [2.3636, -1.5127, 3.60],
    [2.4885, -1.3616, 3.60],
    [2.6045, -1.2033, 3.60],
    [2.7112, -1.0382, 3.60],
    [2.8080, -0.8669, 3.60],
    [2.8973, -0.6914, 3.60],
    [2.9866, -0.5167, 3.60],
    [3.0827, -0.3467, 3.60],
    [3.1829, -0.1789, 3.60],
    [3.2797, -0.0092, 3.60],
    [3.3675, 0.1651, 3.60],
    [3.4452, 0.3441, 3.57],
    [3.5120, 0.5273, 3.60],
    [3.5677, 0.7136, 3.60],
    [3.6124, 0.9015, 3.60],
    [3.6457, 1.0898, 3.48],
    [3.6672, 1.2780, 3.35],
    [3.6760, 1.4644, 3.06],
    [3.6714, 1.6464, 2.76],
    [3.6519, 1.8171, 2.43],
    [3.6176, 1.9684, 2.12],
    [3.5738, 2.0933, 1.79],
    [3.5299, 2.1812, 1.50],
    [3.4758, 2.2557, 1.56],
    [3.3951, 2.3345, 1.69],
    [3.2837, 2.4117, 2.04],
    [3.1467, 2.4812, 2.29],
    [2.9920, 2.5379, 2.58],
    [2.8266, 2.5803, 2.83],
    [2.6532, 2.6094, 3.11],
    [2.4732, 2.6261, 3.15],
    [2.2908, 2.6299, 3.06],
    [2.1079, 2.6198, 3.22],
    [1.9269, 2.5971, 3.33],
    [1.7558, 2.5646, 3.15],
    [1.5906, 2.5215, 3.32],
    [1.4203, 2.4656, 3.11],
    [1.2581, 2.3998, 2.82],
    [1.1146, 2.3281, 2.81],
    [0.9998, 2.2620, 3.03],
    [0.8773, 2.1850, 3.24],
    [0.7439, 2.0907, 3.48],
    [0.6112, 1.9867, 3.60],
    [0.4664, 1.8664, 3.60],
    [0.2949, 1.7332, 3.60],
    [0.0940, 1.5941, 3.49],
    [-0.1087, 1.4606, 3.13],
    [-0.2785, 1.3493, 2.79],
    [-0.3978, 1.2784, 2.77],
    [-0.4928, 1.2238, 2.59],
    [-0.5941, 1.1725, 2.41],
    [-0.7452, 1.1116, 2.72],
    [-0.9159, 1.0545, 3.03],
    [-1.0853, 1.0068, 3.30],
    [-1.2480, 0.9694, 3.49],
    [-1.4096, 0.9407, 3.60],
    [-1.5816, 0.9164, 3.60],
    [-1.7843, 0.8971, 3.60],
    [-2.0122, 0.8839, 3.60],
    [-2.2367, 0.8708, 3.60],
    [-2.4337, 0.8517, 3.50],
    [-2.6068, 0.8250, 3.36],
    [-2.7716, 0.7903, 3.14],
    [-2.9321, 0.7476, 2.87],
    [-3.0808, 0.7015, 2.59],
    [-3.2075, 0.6569, 2.32],
    [-3.3201, 0.6065, 2.23],
    [-3.4262, 0.5459, 1.95],
    [-3.5300, 0.4672, 1.68],
    [-3.6322, 0.3542, 1.93],
    [-3.7193, 0.2172, 1.82],
    [-3.7772, 0.0674, 1.83],
]

_POINTS = len(RACING_LINE)

# The last step's steering command. DeepRacer loads this module once for a whole training, so it
# remembers: a command that changed since the last step costs reward (steady hands).
_last = {"steps": None, "steering": 0.0}


def on_the_line(params):
    """The line at the nearest point says where to be, how fast and which way (to the next
    point): each earns from 0 to 1, and the three are multiplied."""
    if params["is_offtrack"] or not params["all_wheels_on_track"]:
        return 1e-3
    x, y = params["x"], params["y"]
    index = min(
        range(_POINTS), key=lambda k: (RACING_LINE[k][0] - x) ** 2 + (RACING_LINE[k][1] - y) ** 2
    )
    px, py, line_speed = RACING_LINE[index]
    nx, ny, _ = RACING_LINE[(index + 1) % _POINTS]
    length = math.hypot(nx - px, ny - py) or 1e-9

    # Where: the distance from the line through this point and the next; 30% of the track's
    # width from it earns nothing.
    distance = abs((nx - px) * (py - y) - (px - x) * (ny - py)) / length
    on_line = max(1.0 - (distance / (0.3 * params["track_width"])) ** 2, 0.0)

    # How fast: the car rolls 1.029 times the commanded speed (params["speed"]), up to 3.6 m/s,
    # where the wheels stop (any command from 3.5 m/s on). Slower than the line earns less as
    # the speed squared; faster falls away quickly.
    target = 4.0 if line_speed >= 3.55 else line_speed / 1.029
    speed = params["speed"]
    pace = (speed / target) ** 2 if speed <= target else max(1.0 - (speed - target) ** 2, 0.0)

    # Which way: 30 degrees off the line's heading earns nothing.
    off = abs((math.degrees(math.atan2(ny - py, nx - px)) - params["heading"] + 180) % 360 - 180)
    heading = max(1.0 - (off / 30.0) ** 2, 0.0)
    return on_line * pace * heading + 1e-3


def reward_function(params):
    """Follow the racing line at its speed and heading, with steady hands. RACING_LINE above is
    a track's page's "Copy for a reward function": paste your own track's over it. Give the
    action space the line's speeds (1-4 m/s)."""
    steps, steering = params["steps"], params["steering_angle"]
    change = abs(steering - _last["steering"]) if _last["steps"] == steps - 1 else 0.0
    _last.update(steps=steps, steering=steering)
    return on_the_line(params) * max(1.0 - (change / 30.0) ** 2, 0.0) + 1e-3
