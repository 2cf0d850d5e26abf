"""The iteration graph as SVG, drawn on the server: average reward on the left axis, training and
evaluation completion (%) on the right, one point per iteration."""

from __future__ import annotations

from django.utils.html import escape

WIDTH, HEIGHT = 720, 260
LEFT, RIGHT, TOP, BOTTOM = 56, 56, 16, 36
COLOURS = {"reward": "#1d4ed8", "completion": "#b45309", "evaluation": "#15803d"}


def iteration_chart(iterations) -> str:
    """SVG markup for ``iterations`` (Iteration rows in order); empty when there are none."""
    if not iterations:
        return ""
    numbers = [row.number for row in iterations]
    rewards = [row.reward for row in iterations]
    low, high = min(*rewards, 0.0), max(*rewards, 1e-9)
    span_x = max(numbers[-1] - numbers[0], 1)

    def x(number: float) -> float:
        return LEFT + (number - numbers[0]) / span_x * (WIDTH - LEFT - RIGHT)

    def y_reward(value: float) -> float:
        return TOP + (1 - (value - low) / (high - low or 1)) * (HEIGHT - TOP - BOTTOM)

    def y_percent(value: float) -> float:
        return TOP + (1 - value / 100) * (HEIGHT - TOP - BOTTOM)

    def series(points: list[tuple[float, float]], colour: str, label: str) -> str:
        if not points:
            return ""
        path = " ".join(f"{px:.1f},{py:.1f}" for px, py in points)
        dots = "".join(
            f'<circle cx="{px:.1f}" cy="{py:.1f}" r="3" fill="{colour}"/>' for px, py in points
        )
        line = f'<polyline points="{path}" fill="none" stroke="{colour}" stroke-width="2"/>'
        return f'<g aria-label="{label}">{line}{dots}</g>'

    reward = [(x(r.number), y_reward(r.reward)) for r in iterations]
    completion = [(x(r.number), y_percent(r.completion)) for r in iterations]
    evaluation = [
        (x(r.number), y_percent(r.evaluation_completion))
        for r in iterations
        if r.evaluation_completion is not None
    ]
    bottom, right = HEIGHT - BOTTOM, WIDTH - RIGHT
    axes = (
        f'<line x1="{LEFT}" y1="{TOP}" x2="{LEFT}" y2="{bottom}" stroke="#9aa3b5"/>'
        f'<line x1="{right}" y1="{TOP}" x2="{right}" y2="{bottom}" stroke="#9aa3b5"/>'
        f'<line x1="{LEFT}" y1="{bottom}" x2="{WIDTH - RIGHT}" y2="{bottom}" stroke="#9aa3b5"/>'
        f'<text x="{LEFT - 6}" y="{TOP + 4}" text-anchor="end">{high:.3g}</text>'
        f'<text x="{LEFT - 6}" y="{bottom}" text-anchor="end">{low:.3g}</text>'
        f'<text x="{WIDTH - RIGHT + 6}" y="{TOP + 4}">100%</text>'
        f'<text x="{WIDTH - RIGHT + 6}" y="{bottom}">0%</text>'
        f'<text x="{LEFT}" y="{HEIGHT - 8}">iteration {numbers[0]}</text>'
        f'<text x="{WIDTH - RIGHT}" y="{HEIGHT - 8}" text-anchor="end">{numbers[-1]}</text>'
    )
    legend = "".join(
        f'<text x="{LEFT + 8 + i * 210}" y="{TOP + 14}" fill="{COLOURS[key]}">{escape(name)}</text>'
        for i, (key, name) in enumerate(
            (
                ("reward", "Average reward"),
                ("completion", "Training completion %"),
                ("evaluation", "Evaluation completion %"),
            )
        )
    )
    return (
        f'<svg class="chart" viewBox="0 0 {WIDTH} {HEIGHT}" role="img" '
        f'aria-label="Reward and completion per iteration" font-size="12" font-family="sans-serif">'
        f"{axes}{legend}"
        f"{series(reward, COLOURS['reward'], 'Average reward')}"
        f"{series(completion, COLOURS['completion'], 'Training completion')}"
        f"{series(evaluation, COLOURS['evaluation'], 'Evaluation completion')}</svg>"
    )
