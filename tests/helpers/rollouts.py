"""Stand-ins for what ``jobs.rollouts._drive`` is given: a sandbox of several cars that ends
their episodes in a scripted order, and a ``Viewing`` with nobody watching."""

import time

import msgpack

CARS = 3
LENGTHS = (30, 10, 20, 15, 40, 25)  # [steps] of the episodes, in the order they start, cycled


class ScriptedCars:
    """What ``_drive`` uses of a ``Sandbox`` of ``CARS`` cars: each episode takes the next of
    ``LENGTHS`` steps, the cars step together, and ``script[n]`` runs (the trainer, or other
    workers) as the ``n``-th episode ends."""

    def __init__(self, script: dict, cars: int = CARS, pause: float = 0.0) -> None:
        self.cars = cars
        self.pause = pause  # [s] each episode's end takes: lets another worker's thread in
        self.script = script
        self.lengths = (length for _ in range(100) for length in LENGTHS)
        self.driving: dict[int, list] = {}  # car: [steps left, version it started with]
        self.version = -1
        self.loads: list[tuple[int, int]] = []  # (version, cars driving as it was loaded)
        self.started: dict[int, int] = {}  # episodes started, by version
        self.ended: list[int] = []  # each episode's version, in the order they ended

    def set_weights(self, version: int, data: bytes) -> None:
        self.loads.append((version, len(self.driving)))
        self.version = version

    def episode(self, mode: str, worker: int, on_progress, *, start: int) -> dict:
        idle = [car for car in range(self.cars) if car not in self.driving]
        for car in idle[:start]:
            self.driving[car] = [next(self.lengths), self.version]
            self.started[self.version] = self.started.get(self.version, 0) + 1
        time.sleep(self.pause)
        car = min(self.driving, key=lambda car: (self.driving[car][0], car))
        steps, version = self.driving.pop(car)
        for other in self.driving.values():
            other[0] -= steps
        self.ended.append(version)
        self.script.get(len(self.ended), lambda: None)()
        payload = msgpack.packb({"version": version, "car": car})
        return {"payload": payload, "car": car, "driving": len(self.driving)}

    def take_logs(self) -> tuple[list[str], int]:
        return [], 0


class Unwatched:
    """A ``Viewing`` of a job nobody watches: no frames to send."""

    def update(self) -> None: ...
    def hold(self) -> None: ...
    def resume(self) -> None: ...
