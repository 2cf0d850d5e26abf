"""Pitlane's API from Python (``Client``), on the standard library alone.

>>> pitlane = Client("http://127.0.0.1:8000", token="plt_...")
>>> [model["name"] for model in pitlane.models()["items"]]

Every refusal the console answers is raised as ``ApiError``, with its status, machine code and
the words a page would show.
"""

from __future__ import annotations

import json
import urllib.error
import urllib.parse
import urllib.request
import uuid
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

__all__ = ["ApiError", "Client", "folder_files"]

CHUNK = 64 * 1024  # [bytes] read at a time from a download
# A DeepRacer for Cloud model folder's files that describe a model (`pitlane train FOLDER`).
FOLDER_FILES = (
    "model_metadata.json",
    "reward_function.py",
    "hyperparameters.json",
    "training_params.yaml",
)


class ApiError(Exception):
    """A refusal: ``status`` (HTTP), ``code`` (machine), the message (a racer's words), and
    ``errors``: each input at fault, where the console said which."""

    def __init__(
        self, status: int, code: str, message: str, errors: dict[str, str] | None = None
    ) -> None:
        super().__init__(message)
        self.status, self.code, self.errors = status, code, errors or {}
        self.retry_after: int | None = None


def folder_files(folder: Path) -> dict[str, str]:
    """A DeepRacer for Cloud model folder's files, by name, as ``Client.create`` sends them.
    ``training_params_*.yaml`` (DeepRacer for Cloud names one per run) is taken as
    training_params.yaml when that is missing."""
    files = {
        name: (folder / name).read_text() for name in FOLDER_FILES if (folder / name).is_file()
    }
    if "training_params.yaml" not in files:
        runs = sorted(folder.glob("training_params*.yaml"))
        if runs:
            files["training_params.yaml"] = runs[-1].read_text()
    return files


class Client:
    """One console, as one racer's token: each method is one operation of /api/v1/."""

    def __init__(self, url: str, token: str, timeout: float = 60.0) -> None:
        if not url.startswith(("http://", "https://")):
            raise ValueError(f"{url!r} is not a console's address: it starts http:// or https://")
        self.url = url.rstrip("/")
        self.token = token
        self.timeout = timeout

    # Account, models and training

    def me(self) -> dict:
        return self._json("GET", "/me")

    def models(self, **filters: Any) -> dict:
        """Your models, newest first: ``status``, ``track``, ``q``, ``limit``, ``offset``."""
        return self._json("GET", "/models", query=filters)

    def model(self, model_id: int) -> dict:
        return self._json("GET", f"/models/{model_id}")

    def create(self, files: dict[str, str], **fields: Any) -> dict:
        """A model made from DeepRacer's files (``folder_files``), its training queued;
        ``name``, ``description`` and ``max_minutes`` may be given."""
        return self._json("POST", "/models", body={"files": files, **fields})

    def clone(self, model_id: int, name: str, **changes: Any) -> dict:
        return self._json("POST", f"/models/{model_id}/clone", body={"name": name, **changes})

    def stop(self, model_id: int) -> dict:
        return self._json("POST", f"/models/{model_id}/stop")

    def delete(self, model_id: int) -> dict:
        return self._json("DELETE", f"/models/{model_id}")

    def iterations(self, model_id: int) -> list[dict]:
        return self._json("GET", f"/models/{model_id}/iterations")

    def log(self, model_id: int, after: int = 0, limit: int = 500) -> dict:
        """The lines of the model's training log after the line ``after``: ``lines``, ``next``
        (the ``after`` of the next page) and ``active`` (whether more may come)."""
        return self._json("GET", f"/models/{model_id}/log", query={"after": after, "limit": limit})

    def training_events(self, model_id: int) -> Iterator[tuple[str, dict]]:
        """The model's training as it happens: (kind, message) for each server-sent event
        (``state`` first, then ``iteration`` and ``status``), until the training ends."""
        with self._open("GET", f"/models/{model_id}/training/events", timeout=None) as stream:
            kind, data = "message", []
            for raw in stream:
                line = raw.decode().rstrip("\r\n")
                if line.startswith("event:"):
                    kind = line[6:].strip()
                elif line.startswith("data:"):
                    data.append(line[5:].strip())
                elif not line and data:
                    yield kind, json.loads("\n".join(data))
                    kind, data = "message", []

    def validate(self, source: str, track: str = "rookie-loop") -> dict:
        return self._json(
            "POST", "/reward-functions/validate", body={"source": source, "track": track}
        )

    # Evaluations and archives

    def evaluate(self, model_id: int, **settings: Any) -> dict:
        return self._json("POST", f"/models/{model_id}/evaluations", body=settings)

    def evaluation(self, model_id: int, evaluation_id: int) -> dict:
        return self._json("GET", f"/models/{model_id}/evaluations/{evaluation_id}")

    def download(
        self,
        model_id: int,
        kind: str,
        into: Path,
        checkpoint: str = "best",
        progress: Callable[[int, int | None], None] | None = None,
    ) -> Path:
        """Write the model's ``kind`` archive (physical, onnx, virtual, logs) into the folder
        ``into`` under the name the console gives it; ``progress(done, total)`` as it comes."""
        path = f"/models/{model_id}/download/{kind}"
        with self._open("GET", path, query={"checkpoint": checkpoint}) as response:
            name = _attachment_name(response.headers.get("Content-Disposition", ""))
            target = into / (name or f"{kind}-{model_id}.tar.gz")
            total = response.headers.get("Content-Length")
            done = 0
            with target.open("wb") as out:
                for chunk in iter(lambda: response.read(CHUNK), b""):
                    out.write(chunk)
                    done += len(chunk)
                    if progress:
                        progress(done, int(total) if total else None)
        return target

    def import_archive(
        self,
        archive: Path,
        name: str = "",
        progress: Callable[[int, int | None], None] | None = None,
    ) -> dict:
        """Send a model's archive to the import (``progress(done, total)`` as it goes): the
        model when it came with its weights (``"id"`` in the answer), else the preview of the
        model that would train (``"kept"``: pass it to ``import_confirm``)."""
        boundary = f"pitlane-{uuid.uuid4().hex}"
        head = (
            f'--{boundary}\r\nContent-Disposition: form-data; name="name"\r\n\r\n{name}\r\n'
            f'--{boundary}\r\nContent-Disposition: form-data; name="archive"; '
            f'filename="{archive.name}"\r\nContent-Type: application/gzip\r\n\r\n'
        ).encode()
        tail = f"\r\n--{boundary}--\r\n".encode()
        with archive.open("rb") as file:
            body = _Upload([head, file, tail], archive.stat().st_size, progress)
            with self._open(
                "POST",
                "/models/import",
                body=body,
                content_type=f"multipart/form-data; boundary={boundary}",
            ) as response:
                return json.load(response)

    def import_confirm(self, kept: str, **changes: Any) -> dict:
        """Create the previewed model (``name``, ``track``, ``direction``, ``max_minutes`` may
        change), its training queued."""
        return self._json("POST", "/models/import/confirm", body={"kept": kept, **changes})

    def import_cancel(self) -> dict:
        return self._json("DELETE", "/models/import")

    # The league

    def events(self) -> list[dict]:
        return self._json("GET", "/events")

    def leaderboard(self, slug: str, page: int = 1) -> dict:
        return self._json("GET", f"/events/{slug}/leaderboard", query={"page": page})

    def submit(self, model_id: int, event: str, checkpoint: str = "best") -> dict:
        body = {"model": model_id, "checkpoint": checkpoint}
        return self._json("POST", f"/events/{event}/submissions", body=body)

    def runs(self) -> list[dict]:
        return self._json("GET", "/submissions")

    # The wire

    def _json(self, method: str, path: str, *, query=None, body=None) -> Any:
        with self._open(method, path, query=query, body=body) as response:
            return json.load(response)

    def _open(
        self, method: str, path: str, *, query=None, body=None, content_type=None, timeout=0.0
    ):
        """The console's answer; ``body`` is JSON, or with ``content_type`` an ``_Upload``."""
        url = f"{self.url}/api/v1{path}"
        if query:
            url += "?" + urllib.parse.urlencode({k: v for k, v in query.items() if v is not None})
        data = body if content_type or body is None else json.dumps(body).encode()
        request = urllib.request.Request(url, data=data, method=method)  # noqa: S310 (http[s])
        request.add_header("Authorization", f"Bearer {self.token}")
        request.add_header("Accept", "application/json")
        if isinstance(data, _Upload):
            request.add_header("Content-Length", str(data.length))
        if data is not None:
            request.add_header("Content-Type", content_type or "application/json")
        try:
            wait = self.timeout if timeout == 0.0 else timeout  # None: a stream, held open
            return urllib.request.urlopen(request, timeout=wait)  # noqa: S310 (our URL)
        except urllib.error.HTTPError as error:
            raise _refusal(error) from None
        except urllib.error.URLError as error:
            raise ApiError(
                0, "unreachable", f"No console answers at {self.url}: {error.reason}"
            ) from None


class _Upload:
    """A request body sent as it is read: its ``parts`` (bytes, or a file read in chunks), with
    ``progress(done, total)`` [bytes of the file] after each chunk."""

    def __init__(self, parts: list, size: int, progress=None) -> None:
        self.parts, self.size, self.progress = parts, size, progress
        self.length = sum(len(p) if isinstance(p, bytes) else size for p in parts)

    def __iter__(self):
        done = 0
        for part in self.parts:
            if isinstance(part, bytes):
                yield part
                continue
            for chunk in iter(lambda part=part: part.read(CHUNK), b""):
                done += len(chunk)
                yield chunk
                if self.progress:
                    self.progress(done, self.size)


def _refusal(error: urllib.error.HTTPError) -> ApiError:
    try:
        said = json.load(error)
    except ValueError:
        said = {}
    refusal = ApiError(
        error.code,
        said.get("code", "http"),
        said.get("message") or f"The console answered {error.code} {error.reason}.",
        said.get("errors"),
    )
    retry = error.headers.get("Retry-After")
    refusal.retry_after = int(retry) if retry and retry.isdigit() else None
    return refusal


def _attachment_name(disposition: str) -> str | None:
    """The file name of a Content-Disposition header, without any folder in it."""
    for part in disposition.split(";"):
        key, _, value = part.strip().partition("=")
        if key == "filename":
            return Path(value.strip('"')).name or None
    return None
