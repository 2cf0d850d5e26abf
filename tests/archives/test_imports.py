"""Import: a Pitlane virtual model arrives READY and drives like the original; a DeepRacer export
brings its settings and reward function; a hostile archive is refused and leaves nothing."""

from __future__ import annotations

import io
import json
import tarfile

import pytest
import torch
import yaml
from django.core.files.uploadedfile import SimpleUploadedFile
from django.core.management import CommandError, call_command
from django.urls import reverse
from safetensors.torch import save as save_tensors

from archives import deepracer_settings, history, imports
from rl.learner import load_tensors
from tests.helpers.archives import (
    CHECKED_IMPORT,
    DEEPRACER_HYPERPARAMETERS,
    DEEPRACER_METADATA,
    DEEPRACER_PARAMS,
    deepracer_export,
    drfc_layout,
    tar_gz,
    trained_with_history,
    virtual_archive,
)
from tests.helpers.models import ready_model, stored_objects
from training import artifacts, configuration, selectors
from training.configuration import ModelSettings, check
from training.models import RLModel, ShellColour, Track, TrainingJob
from training.rewards import EXAMPLES

pytestmark = pytest.mark.django_db


# TensorFlow files of a car this console does not have: never read (test_deepracer_weights.py
# imports real ones).
UNFIT_WEIGHTS = {
    "model/model_8.pb": b"\x08\x01" * 64,
    "model/8_Step-7040.ckpt.index": b"\x00" * 32,
    "model/8_Step-7040.ckpt.data-00000-of-00001": b"\x00" * 32,
    "model/checkpoint": b'model_checkpoint_path: "8_Step-7040.ckpt"\n',
}


@pytest.mark.slow
def test_a_virtual_model_imports_ready_with_the_same_weights(alice, bob, tracks, tmp_path):
    original = ready_model(alice)
    archive = tmp_path / "virtualmodel-straight-ahead.tar.gz"
    archive.write_bytes(virtual_archive(original))
    out = io.StringIO()
    call_command("importmodel", str(archive), "--owner", "bob", stdout=out)
    assert "Imported straight-ahead" in out.getvalue() and "ready" in out.getvalue()

    model = RLModel.objects.get(owner=bob)
    assert model.status == RLModel.Status.READY
    assert model.metadata() == original.metadata()
    assert model.track.name == "pitlane-oval" and model.reward_function == original.reward_function
    assert model.hyperparameters == original.hyperparameters
    job = model.jobs.get()
    assert job.status == TrainingJob.Status.COMPLETED
    imported = load_tensors(artifacts.read(job.best_checkpoint))
    source = load_tensors(artifacts.read(original.jobs.get().best_checkpoint))
    assert imported.keys() == source.keys()
    assert all(torch.equal(imported[key], source[key]) for key in source)

    # It evaluates like the original: straight ahead, laps with penalties.
    out = io.StringIO()
    call_command("evaluate", str(model.pk), "--trials", "3", stdout=out)
    assert out.getvalue().count("lap_complete") == 3


@pytest.mark.slow
@CHECKED_IMPORT
def test_the_import_page_takes_an_archive_and_a_new_name(alice, tracks, client):
    original = ready_model(alice)
    client.force_login(alice)
    assert "Import a model" in client.get(reverse("archives:model-import")).text
    upload = SimpleUploadedFile("virtualmodel.tar.gz", virtual_archive(original))
    # The name is taken: the page says so and keeps the form.
    response = client.post(reverse("archives:model-import"), {"archive": upload})
    assert response.status_code == 400
    assert "You already have a model named" in response.text
    upload = SimpleUploadedFile("virtualmodel.tar.gz", virtual_archive(original))
    response = client.post(reverse("archives:model-import"), {"archive": upload, "name": "again"})
    model = RLModel.objects.get(owner=alice, name="again")
    assert response.status_code == 302 and response["Location"].endswith(f"/models/{model.pk}/")
    assert model.status == RLModel.Status.READY
    clone = client.get(reverse("training:model-create") + f"?clone={model.pk}")
    assert 'value="again-clone"' in clone.text  # it clones like the original


def test_a_deepracer_export_for_a_car_we_lack_brings_its_settings_and_trains_anew(
    alice, tracks, tmp_path
):
    metadata = {**DEEPRACER_METADATA, "sensor": ["FRONT_FACING_CAMERA", "DISCRETIZED_SECTOR_LIDAR"]}
    archive = tmp_path / "deepracer.tar.gz"
    archive.write_bytes(
        tar_gz(
            deepracer_export(
                **UNFIT_WEIGHTS,
                **{
                    "model_metadata.json": json.dumps(metadata).encode(),
                },
            )
        )
    )
    out = io.StringIO()
    call_command("importmodel", str(archive), "--owner", "alice", stdout=out)
    said = out.getvalue()
    assert "queued for training" in said
    assert "TensorFlow weights were not carried over: they are for sensors" in said
    assert "the track H_track, which is not loaded here" in said
    model = RLModel.objects.get(owner=alice)
    assert model.name == "my-deepracer-car" and model.status == RLModel.Status.QUEUED
    assert [a["speed"] for a in model.action_space] == [0.6, 1.2, 0.6]
    assert model.hyperparameters == {**DEEPRACER_HYPERPARAMETERS, "loss_type": "huber"}
    assert model.reward_function == EXAMPLES[0].source
    assert model.jobs.get().status == TrainingJob.Status.QUEUED


def symlink(tar):
    info = tarfile.TarInfo("agent/link")
    info.type, info.linkname = tarfile.SYMTYPE, "/etc/passwd"
    tar.addfile(info)


def hardlink(tar):
    info = tarfile.TarInfo("hard")
    info.type, info.linkname = tarfile.LNKTYPE, "model_metadata.json"
    tar.addfile(info)


def device(tar):
    info = tarfile.TarInfo("dev/null")
    info.type, info.devmajor, info.devminor = tarfile.CHRTYPE, 1, 3
    tar.addfile(info)


def fifo(tar):
    info = tarfile.TarInfo("pipe")
    info.type = tarfile.FIFOTYPE
    tar.addfile(info)


def pax_header(tar):
    info = tarfile.TarInfo("notes.txt")
    info.pax_headers = {"comment": "x" * 2_000_000}  # read whole by tarfile, never a member
    tar.addfile(info, io.BytesIO(b""))


def pax_headers(tar):
    for n in range(40):  # each under the limit of one, over the archive's together
        info = tarfile.TarInfo(f"notes-{n}.txt")
        info.pax_headers = {"comment": "x" * 30_000}
        tar.addfile(info, io.BytesIO(b""))


def long_name(tar):
    tar.format = tarfile.GNU_FORMAT  # a GNU long-name header
    tar.addfile(tarfile.TarInfo("a/" * 5000 + "x"), io.BytesIO(b""))


def wrong_shapes() -> bytes:
    return save_tensors({"action_net.weight": torch.zeros(7, 64), "action_net.bias": torch.ones(7)})


DQN_METADATA = json.dumps({**DEEPRACER_METADATA, "training_algorithm": "dqn"}).encode()
HOSTILE = {
    "absolute path": (tar_gz(deepracer_export(**{"/etc/cron.d/x": b"x"})), "not a relative path"),
    "parent folder": (tar_gz(deepracer_export(**{"../../x.py": b"x"})), "not a relative path"),
    "symbolic link": (tar_gz(deepracer_export(), symlink), "is a link or a device"),
    "hard link": (tar_gz(deepracer_export(), hardlink), "is a link or a device"),
    "device": (tar_gz(deepracer_export(), device), "is a link or a device"),
    "fifo": (tar_gz(deepracer_export(), fifo), "is a link or a device"),
    "huge pax header": (tar_gz(deepracer_export(), pax_header), "header over 65,536 bytes"),
    "many pax headers": (tar_gz(deepracer_export(), pax_headers), "extended header over 1 MiB"),
    "long name": (tar_gz(deepracer_export(), long_name), "name of 10,001 characters"),
    "not an archive": (b"PK\x03\x04 a zip, or anything", "not a .tar.gz model archive"),
    "no metadata": (tar_gz({"reward_function.py": b"x"}), "no model_metadata.json"),
    "bad metadata": (tar_gz(deepracer_export(**{"model_metadata.json": b"{"})), "not valid JSON"),
    "unknown algorithm": (
        tar_gz(deepracer_export(**{"model_metadata.json": DQN_METADATA})),
        "this console trains PPO",
    ),
    "reward function that does not compile": (
        tar_gz(deepracer_export(**{"reward_function.py": b"def reward_function(params:\n"})),
        "Reward function: syntax (line 1): '(' was never closed",
    ),
    "weights for another network": (
        tar_gz({**deepracer_export(), "checkpoints/best.safetensors": wrong_shapes()}),
        "does not fit the model's network",
    ),
    "weights that are not safetensors": (
        tar_gz({**deepracer_export(), "checkpoints/last.safetensors": b"\x80\x04pickle"}),
        "does not fit the model's network",
    ),
}


@pytest.mark.slow
@pytest.mark.parametrize("case", HOSTILE)
@CHECKED_IMPORT
def test_a_bad_archive_is_refused_with_its_reason_and_leaves_nothing(
    case, alice, tracks, client, own_storage
):
    data, reason = HOSTILE[case]
    before = stored_objects()
    client.force_login(alice)
    response = client.post(
        reverse("archives:model-import"), {"archive": SimpleUploadedFile("model.tar.gz", data)}
    )
    assert response.status_code == 400
    assert reason in response.text.replace("&#x27;", "'")
    assert "Traceback" not in response.text
    assert not RLModel.objects.exists() and not TrainingJob.objects.exists()
    assert stored_objects() == before


@pytest.mark.parametrize(
    ("limit", "value", "reason"),
    [("MAX_MEMBERS", 3, "holds over 3 files"), ("MAX_UNPACKED", 100, "unpacks to over")],
)
def test_archive_limits(limit, value, reason, alice, tracks, tmp_path, monkeypatch):
    monkeypatch.setattr(imports, limit, value)
    archive = tmp_path / "big.tar.gz"
    archive.write_bytes(tar_gz(deepracer_export()))
    with pytest.raises(CommandError, match=reason):
        call_command("importmodel", str(archive), "--owner", "alice")
    assert not RLModel.objects.exists()


def test_an_archive_over_the_upload_limit_is_refused_before_it_is_read(alice, client, monkeypatch):
    monkeypatch.setattr(imports, "MAX_ARCHIVE", 1024)
    client.force_login(alice)
    upload = SimpleUploadedFile("model.tar.gz", b"\x1f\x8b" + bytes(4096))
    response = client.post(reverse("archives:model-import"), {"archive": upload})
    assert response.status_code == 400
    assert "The archive is over" in response.text


@pytest.mark.slow
@CHECKED_IMPORT
def test_an_imported_virtual_model_keeps_its_training_history(alice, bob, tracks, client):
    upload = SimpleUploadedFile("virtualmodel.tar.gz", virtual_archive(trained_with_history(alice)))
    client.force_login(bob)
    response = client.post(reverse("archives:model-import"), {"archive": upload})
    model = RLModel.objects.get(owner=bob)
    assert response.status_code == 302
    job = model.jobs.get()
    assert (job.status, job.iterations, job.episodes) == (TrainingJob.Status.COMPLETED, 2, 6)
    assert job.steps == 5 * 30 + 60 and round(job.training_seconds) == 150
    first, second = job.iteration_rows.all()
    assert (first.number, first.reward, first.completion) == (1, 12.0, 20.0)
    assert first.training_points == [[11.0, 20.0], [12.0, 20.0], [13.0, 20.0]]
    assert first.evaluation_completion == 45.0 and first.evaluation_points == [40.0, 50.0]
    assert first.best_lap_time is None and second.best_lap_time == 4.0
    assert second.evaluation_completion == 75.0
    # The racer sees it: the list says how long it trained, the page has the graph's history.
    listing = client.get(reverse("training:model-list")).text
    assert "Completed after 2:30 of 60 min, 2 iterations" in listing
    page = client.get(reverse("training:model-detail", args=[model.pk])).text
    assert "2 iterations, 6 episodes, 210 steps" in page
    assert "data-live-no-iterations hidden" in page  # the table and graph have rows
    assert "Training metrics (JSON)" in page  # kept, and carried by the next download
    # Time trained elsewhere is not taken from the racer's monthly allowance.
    assert selectors.allowance_for(racer=bob).minutes == 0


DEEPRACER_METRICS = {
    "version": "2",
    "best_model_metric": "progress",
    "metrics": [
        {
            "reward_score": 5,
            "metric_time": 1000,
            "start_time": 0,
            "elapsed_time_in_milliseconds": 1000,
            "episode": 1,
            "trial": 1,
            "phase": "training",
            "completion_percentage": 10,
            "episode_status": "Off track",
        },
        {
            "reward_score": 7,
            "metric_time": 9000,
            "start_time": 1000,
            "elapsed_time_in_milliseconds": 8000,
            "episode": 2,
            "trial": 2,
            "phase": "training",
            "completion_percentage": 100,
            "episode_status": "Lap complete",
        },
        # DeepRacer's evaluation rows repeat the last training episode's numbers.
        {
            "reward_score": 0,
            "metric_time": 12000,
            "start_time": 9000,
            "elapsed_time_in_milliseconds": 3000,
            "episode": 2,
            "trial": 2,
            "phase": "evaluation",
            "completion_percentage": 60,
            "episode_status": "Crashed",
        },
        {
            "reward_score": 9,
            "metric_time": 14000,
            "start_time": 12000,
            "elapsed_time_in_milliseconds": 2000,
            "episode": 3,
            "trial": 1,
            "phase": "training",
            "completion_percentage": 30,
            "episode_status": "Off track",
        },
    ],
}


def test_deepracers_own_metrics_read_as_iterations():
    found = history.read(json.dumps(DEEPRACER_METRICS).encode(), episodes_per_iteration=20)
    first, second = found.iterations
    assert (first.episodes, first.reward, first.best_lap_time) == (2, 6.0, 8.0)
    assert first.evaluation_points == [60.0] and second.evaluation_completion is None
    assert (second.episodes, second.steps) == (1, 30)
    assert found.seconds == 14.0 and found.episodes == 3


@pytest.mark.slow
def test_a_virtual_model_without_readable_metrics_imports_without_history_and_says_so(
    alice, bob, tracks
):
    members = {}
    with tarfile.open(fileobj=io.BytesIO(virtual_archive(ready_model(alice))), mode="r:gz") as tar:
        for member in tar:
            members[member.name] = tar.extractfile(member).read()
    cases = {
        "none": (None, "The archive has no training metrics"),
        "not-json": (b"{not json", "training metrics could not be read"),
        "no-iterations": (b'{"metrics": [{"phase": "training"}]}', "could not be read"),
    }
    for name, (metrics, said) in cases.items():
        members.pop(artifacts.TRAINING_METRICS, None)
        if metrics is not None:
            members[artifacts.TRAINING_METRICS] = metrics
        imported = imports.import_model(owner=bob, archive=io.BytesIO(tar_gz(members)), name=name)
        assert imported.model.status == RLModel.Status.READY
        assert any(said in note for note in imported.notes), name
        job = imported.model.jobs.get()
        assert job.iterations == 0 and not job.iteration_rows.exists()


def test_a_file_that_is_not_an_archive_is_refused_in_a_racers_words(alice, client):
    client.force_login(alice)
    upload = SimpleUploadedFile("notes.txt", b"just some notes, not a model")
    response = client.post(reverse("archives:model-import"), {"archive": upload})
    assert response.status_code == 400
    assert "This file is not a .tar.gz model archive" in response.text
    for python in ("file could not be opened", "not a gzip file", "tarfile", "Error"):
        assert python not in response.text
    assert "you uploaded" not in response.text  # a refused file is not kept


@pytest.mark.slow
@CHECKED_IMPORT
def test_a_taken_name_is_said_before_the_archive_is_read_and_the_upload_is_kept(
    alice, tracks, client
):
    original = ready_model(alice)
    client.force_login(alice)
    page = client.get(reverse("archives:model-import")).text
    assert page.index('name="name"') < page.index('name="archive"')  # the name comes first
    check = client.get(reverse("training:model-name-check"), {"name": "Straight-Ahead"}).json()
    assert check["ok"] is False and "You already have a model named" in check["message"]
    assert client.get(reverse("training:model-name-check"), {"name": "fresh"}).json()["ok"]

    # A taken name with a file that is no archive: the name is what the page talks about.
    upload = SimpleUploadedFile("model.tar.gz", b"not read yet")
    response = client.post(
        reverse("archives:model-import"), {"name": "straight-ahead", "archive": upload}
    )
    assert response.status_code == 400
    assert "You already have a model named" in response.text
    assert "not a .tar.gz model archive" not in response.text

    # The archive chosen is kept: correcting the name is enough.
    upload = SimpleUploadedFile("virtualmodel.tar.gz", virtual_archive(original))
    response = client.post(
        reverse("archives:model-import"), {"name": "straight-ahead", "archive": upload}
    )
    assert "Using <strong>virtualmodel.tar.gz</strong> you uploaded" in response.text
    assert 'value="straight-ahead"' in response.text
    kept = response.context["form"].kept_upload
    assert artifacts.default_storage.exists(kept.name)
    response = client.post(reverse("archives:model-import"), {"name": "again", "kept": kept.token})
    assert response.status_code == 302
    assert RLModel.objects.get(owner=alice, name="again").status == RLModel.Status.READY
    assert not artifacts.default_storage.exists(kept.name)  # cleaned up once used

    # Without a file or a kept one, the page asks for one.
    response = client.post(reverse("archives:model-import"), {"name": "third", "kept": "stale"})
    assert response.status_code == 400 and "Choose the model&#x27;s archive" in response.text


@pytest.mark.slow
def test_a_kept_archive_is_another_racers_to_use_never(alice, bob, tracks, client):
    client.force_login(alice)
    upload = SimpleUploadedFile("virtualmodel.tar.gz", virtual_archive(ready_model(alice)))
    response = client.post(
        reverse("archives:model-import"), {"name": "straight-ahead", "archive": upload}
    )
    token = response.context["form"].kept_upload.token
    client.force_login(bob)
    response = client.post(reverse("archives:model-import"), {"name": "mine", "kept": token})
    assert response.status_code == 400 and not RLModel.objects.filter(owner=bob).exists()


@CHECKED_IMPORT
def test_an_archive_at_fault_is_not_kept_for_the_next_attempt(alice, tracks, client):
    client.force_login(alice)
    bad_reward = deepracer_export(**{"reward_function.py": b"def reward_function(params:\n"})
    upload = SimpleUploadedFile("model.tar.gz", tar_gz(bad_reward))
    response = client.post(reverse("archives:model-import"), {"archive": upload})
    assert response.status_code == 400 and "Reward function: syntax" in response.text
    assert response.context["form"].kept_upload is None and "you uploaded" not in response.text


LAYOUTS = {
    "the root": lambda members: members,
    "DeepRacer for Cloud's model/ and ip/": drfc_layout,
    "model/ and ip/ only, no root metadata": lambda members: {
        key: value for key, value in drfc_layout(members).items() if key != "model_metadata.json"
    },
    "one top folder": lambda members: {
        f"DeepRacer-SageMaker-RoboMaker-comm-123/{key}": value
        for key, value in drfc_layout(members).items()
    },
}


@pytest.mark.slow
@pytest.mark.parametrize("layout", LAYOUTS)
def test_a_deepracer_model_imports_from_each_layout_with_every_hyperparameter(
    layout, alice, tracks
):
    hyper = {**DEEPRACER_HYPERPARAMETERS, "loss_type": "mean squared error", "sac_alpha": 0.2}
    params = {**DEEPRACER_PARAMS, "WORLD_NAME": "pitlane-oval_cw"}
    members = deepracer_export(
        **{
            "hyperparameters.json": json.dumps(hyper).encode(),
            "training_params.yaml": yaml.safe_dump(params).encode(),
        }
    )
    imported = imports.import_model(
        owner=alice, archive=io.BytesIO(tar_gz(LAYOUTS[layout](members)))
    )
    model = imported.model
    # Kept too: stack_size, exploration_type, e_greedy_value, epsilon_steps, term_cond_*, and
    # sac_alpha, which DeepRacer for Cloud writes for PPO models as well.
    assert model.hyperparameters == hyper
    assert (model.track.name, model.direction) == ("pitlane-oval", "clockwise")
    assert [a["steering_angle"] for a in model.action_space] == [-30.0, 0.0, 30.0]
    assert not [note for note in imported.notes if "hyperparameters" in note or "track" in note]


def track_row(name: str, **changes) -> Track:
    fields = {
        "display_name": name,
        "difficulty": "beginner",
        "length_m": 20.0,
        "width_m": 1.0,
        "counterclockwise": True,
        "clockwise": True,
        **changes,
    }
    return Track.objects.create(name=name, **fields)


DROVE = "Trains on {} ({} waypoints), the route file DeepRacer drove for WORLD_NAME "


@pytest.mark.parametrize(
    ("params", "expected", "noted"),
    [
        # DeepRacer for Cloud's bare name: simapp drove reInvent2019_track.npy (154 waypoints),
        # the console drives reInvent2019_track_ccw.npy (79): the model keeps simapp's file.
        ({"WORLD_NAME": "reInvent2019_track"},
         ("reInvent2019_track", "counterclockwise", "reInvent2019_track"),
         DROVE.format("reInvent2019_track.npy", 154) + "reInvent2019_track, not the one"),
        ({"WORLD_NAME": "reInvent2019_track_cw"}, ("reInvent2019_track", "clockwise", ""), ""),
        ({"WORLD_NAME": "reInvent2019_track_ccw"},
         ("reInvent2019_track", "counterclockwise", ""), ""),
        # REVERSE_DIR drives the file named backwards, which is not the _cw file's order.
        ({"WORLD_NAME": "reInvent2019_track_ccw", "REVERSE_DIR": True},
         ("reInvent2019_track", "clockwise", "reInvent2019_track_ccw"),
         DROVE.format("reInvent2019_track_ccw.npy", 79)),
        # TRACK_DIRECTION_CLOCKWISE suffixes the name: simapp drove the console's file.
        ({"WORLD_NAME": "reInvent2019_track", "TRACK_DIRECTION_CLOCKWISE": "true"},
         ("reInvent2019_track", "clockwise", ""), ""),
        ({"WORLD_NAME": "reInvent2019_track", "TRACK_DIRECTION_CLOCKWISE": False,
          "REVERSE_DIR": "True"}, ("reInvent2019_track", "clockwise", "reInvent2019_track_ccw"),
         DROVE.format("reInvent2019_track_ccw.npy", 79)),
        # The exact name comes first: a track whose own name ends in _cw.
        ({"WORLD_NAME": "Oval_cw"}, ("Oval_cw", "counterclockwise", ""), ""),
        # Then lower-case, with hyphens for underscores; the suffix still gives the direction.
        ({"WORLD_NAME": "Kidney_Bean_cw"}, ("kidney-bean", "clockwise", ""), ""),
        ({"WORLD_NAME": "One_Way_cw"}, ("one-way", "counterclockwise", ""),
         "One Way is not driven clockwise here: the model drives it counter-clockwise."),
        ({"WORLD_NAME": "monza_ccw"}, ("rookie-loop", "counterclockwise", ""),
         "Not carried over from training_params.yaml: the track monza_ccw, which is not loaded "
         "here. The model trains on Rookie Loop;"),  # its display name, not its slug
    ],
)  # fmt: skip
def test_world_name_finds_the_loaded_track_and_its_direction(params, expected, noted):
    for name in ("reInvent2019_track", "Oval_cw", "Oval", "kidney-bean"):
        track_row(name)
    track_row("rookie-loop", display_name="Rookie Loop")
    track_row("one-way", display_name="One Way", clockwise=False)
    notes = []
    assert deepracer_settings.deepracer_track(params, notes) == expected
    if noted:
        assert len(notes) == 1 and noted in notes[0], notes
    else:
        assert notes == []


@pytest.mark.parametrize(
    ("params", "expected", "noted"),
    [
        ({"WORLD_NAME": "2022_april_open_cw"}, ("2022_april_open", "clockwise", ""), ""),
        # simapp drove 2022_april_open_cw.npy (yaml_file.py:228-246), as the console does.
        ({"WORLD_NAME": "2022_april_open", "TRACK_DIRECTION_CLOCKWISE": True},
         ("2022_april_open", "clockwise", ""), ""),
        # Without a suffix, the file's own way, though the console offered it clockwise first.
        ({"WORLD_NAME": "reInvent2019_wide"},
         ("reInvent2019_wide", "counterclockwise", "reInvent2019_wide"),
         DROVE.format("reInvent2019_wide.npy", 111)),
        ({"WORLD_NAME": "reinvent_carpet", "REVERSE_DIR": True},
         ("reinvent_carpet", "clockwise", ""), ""),
        ({"WORLD_NAME": "Albert", "TRACK_DIRECTION_CLOCKWISE": False}, ("Albert", "clockwise", ""),
         "Yun Speedway is not driven counter-clockwise here: the model drives it clockwise."),
    ],
)  # fmt: skip
def test_a_deepracer_world_name_lands_on_the_built_in_track_and_its_direction(
    tracks, params, expected, noted
):
    notes = []
    assert deepracer_settings.deepracer_track(params, notes) == expected
    if noted:
        assert len(notes) == 1 and noted in notes[0], notes
    else:
        assert notes == []


def imported_by_command(tmp_path, world_name: str, owner) -> RLModel:
    """A DeepRacer export trained on ``world_name`` (its training_params.yaml's WORLD_NAME),
    imported for ``owner`` by ``manage.py importmodel``."""
    archive = tmp_path / "deepracer.tar.gz"
    params = {**DEEPRACER_PARAMS, "WORLD_NAME": world_name}
    members = deepracer_export(**{"training_params.yaml": yaml.safe_dump(params).encode()})
    archive.write_bytes(tar_gz(members))
    call_command("importmodel", str(archive), "--owner", owner.username, stdout=io.StringIO())
    return RLModel.objects.get(owner=owner)


def test_a_bare_world_name_trains_on_simapps_own_file_and_a_clone_on_that_track_keeps_it(
    alice, tracks, tmp_path, client
):
    model = imported_by_command(tmp_path, "reInvent2019_track", alice)  # DeepRacer for Cloud's
    assert (model.track.name, model.direction, model.world_name) == (
        "reInvent2019_track",
        "counterclockwise",
        "reInvent2019_track",
    )
    assert any(
        note.startswith("Trains on reInvent2019_track.npy (154 waypoints)")
        for note in model.import_notes
    )
    assert model.environment_settings()["route"] == "reInvent2019_track"
    client.force_login(alice)
    page = client.get(reverse("training:model-detail", args=[model.pk])).text
    assert "(counter-clockwise, on DeepRacer's route file reInvent2019_track.npy)" in page
    assert model.environment_settings("pitlane-oval")["route"] is None  # another track's route
    model.status = RLModel.Status.READY  # as once its training ends: a clone's source
    clone = {
        **ModelSettings.of(model).draft(),
        "name": "clone",
        "world_name": "",
        "cloned_from": model,
    }
    assert check(clone, owner=alice, validate_reward=False).world_name == "reInvent2019_track"
    elsewhere = {**clone, "track": "2022_april_open"}
    assert check(elsewhere, owner=alice, validate_reward=False).world_name == ""


def test_a_deepracer_export_imports_onto_its_own_track(alice, tracks, tmp_path):
    model = imported_by_command(tmp_path, "reInvent2019_track_cw", alice)
    assert (model.track.display_name, model.direction) == ("Smile Speedway", "clockwise")
    assert not [note for note in model.import_notes if "track" in note.lower()]


@CHECKED_IMPORT
def test_every_setting_that_is_not_carried_over_is_listed_on_the_result_page(alice, tracks, client):
    metadata = {
        **DEEPRACER_METADATA,
        "sensor": ["FRONT_FACING_CAMERA", "DISCRETIZED_SECTOR_LIDAR"],
        "neural_network": "DEEP_CONVOLUTIONAL_NETWORK_DEEP",
        "lidar_config": {"num_sectors": 8, "clipping_dist": 2.0},
    }
    hyper = {**DEEPRACER_HYPERPARAMETERS, "num_epochs": 20, "clip_range": 0.3}
    params = {
        **DEEPRACER_PARAMS,
        "WORLD_NAME": "pitlane-oval",
        "RACE_TYPE": "OBJECT_AVOIDANCE",
        "NUMBER_OF_OBSTACLES": 9,
        "RANDOMIZE_OBSTACLE_LOCATIONS": "True",
        "OBJECT_POSITIONS": ["0.2,-1", "0.5,1"],
        "CHANGE_START_POSITION": True,
        "NUM_WORKERS": 6,
        "CAR_COLOR": "Purple",
        "BODY_SHELL_TYPE": "f1_2021",
        "SAGEMAKER_SHARED_S3_BUCKET": "bucket",
        "SAGEMAKER_SHARED_S3_PREFIX": "rl-deepracer",
        "AWS_REGION": "us-east-1",
    }
    members = deepracer_export(
        **UNFIT_WEIGHTS,
        **{
            "model_metadata.json": json.dumps(metadata).encode(),
            "hyperparameters.json": json.dumps(hyper).encode(),
            "training_params.yaml": yaml.safe_dump(params).encode(),
        },
    )
    client.force_login(alice)
    upload = SimpleUploadedFile("model.tar.gz", tar_gz(drfc_layout(members)))
    preview = client.post(reverse("archives:model-import"), {"archive": upload})
    assert not RLModel.objects.exists()  # no weights: it trains, once the racer confirms
    confirmed = {**preview.context["confirm"].data, "confirm": "1"}
    response = client.post(reverse("archives:model-import"), confirmed, follow=True)
    listed = [
        "Not carried over from hyperparameters.json: num_epochs 20. Number of epochs must be "
        "between 3 and 10. The model uses 10.",
        "Not carried over from hyperparameters.json: clip_range 0.3: not one of DeepRacer's "
        "hyperparameters.",
        "Not carried over from model_metadata.json: the sensor DISCRETIZED_SECTOR_LIDAR.",
        "Not carried over from model_metadata.json: the network DEEP_CONVOLUTIONAL_NETWORK_DEEP.",
        'Not carried over from model_metadata.json: lidar_config {"num_sectors": 8, '
        '"clipping_dist": 2.0}.',
        "Not carried over from training_params.yaml: NUMBER_OF_OBSTACLES 9, "
        "RANDOMIZE_OBSTACLE_LOCATIONS True (",
        "Not carried over from training_params.yaml: NUM_WORKERS 6. A model trains in 1 to 4",
        'OBJECT_POSITIONS ["0.2,-1", "0.5,1"]',
        "CHANGE_START_POSITION true",
        "BODY_SHELL_TYPE f1_2021",
        "(AWS_REGION, SAGEMAKER_SHARED_S3_BUCKET, SAGEMAKER_SHARED_S3_PREFIX); this console keeps",
        "TensorFlow weights were not carried over",
    ]
    for page in (preview.text, response.text):  # on the preview, then on the result page
        page = page.replace("&quot;", '"').replace("&#x27;", "'")
        for note in listed:
            assert note in page, note
    model = RLModel.objects.get(owner=alice)
    assert (model.sensors, model.network) == (
        ["FRONT_FACING_CAMERA"],
        "DEEP_CONVOLUTIONAL_NETWORK_SHALLOW",
    )
    assert model.boxes == {"count": 3, "randomize": False} and model.race_type == "OBJECT_AVOIDANCE"
    assert (model.workers, model.shell_colour) == (4, ShellColour.PURPLE)
    assert model.hyperparameters["num_epochs"] == 10
    assert model.hyperparameters["term_cond_avg_score"] == 350.0


@pytest.mark.slow
def test_our_own_export_round_trips_every_hyperparameter_in_deepracers_spelling(alice, bob, tracks):
    original = ready_model(alice)
    stored = {
        **original.hyperparameters,
        "loss_type": "mse",
        "term_cond_avg_score": 350.0,
        "exploration_type": "e-greedy",
        "sac_alpha": 0.3,
        "discount_factor": 0.99,
    }
    stored.pop("stack_size")  # a model from before the kept keys: the export fills them in
    # every setting pitlane.json carries (the declared list's), away from its default
    carried = {
        "description": "Round trip.",
        "race_type": "OBJECT_AVOIDANCE",
        "boxes": {"count": 4, "randomize": True},
        "shell_colour": ShellColour.ORANGE,
        "max_minutes": 30,
        "seed": 7,
        "best_checkpoint_by": "reward",
        "camera_lens": "wide",
        "domain_randomisation": True,
    }
    RLModel.objects.filter(pk=original.pk).update(hyperparameters=stored, **carried)
    original.refresh_from_db()
    members = {}
    with tarfile.open(fileobj=io.BytesIO(virtual_archive(original)), mode="r:gz") as tar:
        for member in tar:
            members[member.name] = tar.extractfile(member).read()
    written = members["ip/hyperparameters.json"]
    assert members["hyperparameters.json"] == written
    expected = {**stored, "loss_type": "mean squared error", "stack_size": 1}
    assert json.loads(written) == expected
    assert list(json.loads(written)) == sorted(expected)  # as simapp writes it: sorted keys
    imported = imports.import_model(owner=bob, archive=io.BytesIO(virtual_archive(original)))
    assert imported.model.hyperparameters == expected
    for name in configuration.ARCHIVED:  # pitlane.json carries them
        assert getattr(imported.model, name) == getattr(original, name), name
    assert imported.model.boxes == carried["boxes"] and imported.model.camera_lens == "wide"
    assert not [note for note in imported.notes if "carried over" in note]


@pytest.mark.parametrize(
    ("track", "direction", "world_name"),
    [("2022_april_open", "clockwise", ""), ("Albert", "clockwise", ""),
     ("reinvent_carpet", "clockwise", ""), ("pitlane-oval", "counterclockwise", ""),
     ("reInvent2019_track", "counterclockwise", "reInvent2019_track"),
     ("reInvent2019_track", "clockwise", "reInvent2019_track_ccw")],
)  # fmt: skip
def test_an_exported_track_names_deepracers_world_and_imports_back_onto_itself(
    alice, tracks, track, direction, world_name
):
    model = RLModel(
        owner=alice,
        name="round-trip",
        track=Track.objects.get(name=track),
        direction=direction,
        world_name=world_name,
    )
    params = artifacts.training_params(model)
    if track == "2022_april_open":  # the file DeepRacer drives clockwise, not the base reversed,
        # named as DeepRacer on AWS names it (SimulationEnvironmentHelper.ts:53-56)
        said = (params["WORLD_NAME"], params["REVERSE_DIR"], params["TRACK_DIRECTION_CLOCKWISE"])
        assert said == ("2022_april_open", False, True)
    if world_name:  # its own file, backwards where it runs the other way
        reverse = world_name.endswith("_ccw")
        assert (params["WORLD_NAME"], params["REVERSE_DIR"]) == (world_name, reverse)
    notes = []
    assert deepracer_settings.deepracer_track(params, notes) == (track, direction, world_name)
    assert len(notes) == bool(world_name)
