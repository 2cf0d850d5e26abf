"""What domain randomisation varies and by how much: the ranges ``simulator.randomisation``
draws each episode's look from, and the words the pages say them in. Apart from the drawing,
which needs OpenCV, so that the web tier can say what a randomised scene is without loading it
(tests/console/test_layers.py)."""

LUMA = (0.2989, 0.5870, 0.1140)  # r, g, b: rl_coach observation_rgb_to_y_filter.py:45
COLOUR_RANGE = (0.0, 1.0)  # r, g, b of a light or an object: light_randomizer.py:56-58,
# model_visual_randomizer.py:71-73
# A light's colour sets how bright the scene is: a black light leaves the ambient share of it,
# a white one gives it all and more (ours; simapp's attenuation terms, 0-1 each at
# light_randomizer.py:59-61, have no counterpart in a flat picture, so an intensity stands in).
AMBIENT = 0.6  # brightness under a black light
LIGHT_GAIN = 0.8  # brightness added by a white light's luma of 1
INTENSITY = (0.85, 1.15)  # [x] the light's strength
# Ours: each gray level that a part of the track image is drawn in (surface, borders, centre
# line, ground...) moves by up to this much, independently: texture.Style's road is darker
# than its borders by well over twice this, so the surface stays far darker than the borders.
PART_SHIFT = 40  # [gray levels of 255]
TEXTURE_STRENGTH = (0.0, 0.12)  # [x] a mottled texture brightens or darkens by up to this
TEXTURE_SIZE = (0.2, 1.0)  # [m] the size of its patches
NOISE = (0.0, 4.0)  # [gray levels] the standard deviation of the camera's noise, each frame
BLUR = (0.0, 0.8)  # [px] the standard deviation of the camera's blur
# The camera mount, moved by up to: forward [m], height [m], pitch [deg], left [m].
MOUNT_JITTER = (0.005, 0.005, 1.0, 0.002)
FRICTION = (0.9, 1.1)  # [x] the tyres' grip (mu 0.5, racecar.gazebo:11-45): 0.45-0.55
MOTOR = (0.98, 1.02)  # [x] the wheels' speed for a given command: a calibration error
SHADES = 16  # objects given colours of their own; more take them in turn


SUMMARY = "light, colours, textures, camera noise and blur, a little camera, grip and motor jitter"


def describe() -> list[tuple[str, str]]:
    """What a randomised episode varies and by how much, in a racer's words (the model page)."""
    low, high = AMBIENT * INTENSITY[0], (AMBIENT + LIGHT_GAIN) * INTENSITY[1]
    forward, height, pitch, left = MOUNT_JITTER
    return [
        ("Light", f"colour r, g, b each 0-1 as simapp's; brightness x{low:.2f}-{high:.2f}"),
        ("Boxes and bot cars", "a colour each, r, g, b each 0-1 as simapp's"),
        ("Track and ground", f"each part's gray level ±{PART_SHIFT}; a mottled texture up to "
                             f"±{TEXTURE_STRENGTH[1]:.0%} in patches of {TEXTURE_SIZE[0]}-"
                             f"{TEXTURE_SIZE[1]} m"),
        ("Camera", f"noise sd 0-{NOISE[1]:g} gray levels, blur sd 0-{BLUR[1]:g} px; mount "
                   f"±{forward * 1000:g} mm forward, ±{height * 1000:g} mm up, ±{pitch:g}° "
                   f"pitch, ±{left * 1000:g} mm sideways"),
        ("Car", f"tyre grip x{FRICTION[0]:g}-{FRICTION[1]:g}, motor x{MOTOR[0]:g}-{MOTOR[1]:g}"),
    ]  # fmt: skip
