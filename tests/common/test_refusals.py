"""One refusal type: views and commands catch ``Refused`` and show what it says."""

from archives import exports, imports, logs_archive
from common.refusals import WHOLE, Refused
from racing.services import SubmissionRefused
from training import configuration, services


def test_a_refusal_reads_as_one_sentence_or_one_line_per_input():
    whole = Refused("This model has no trained weights yet: train it first.")
    assert whole.errors == {WHOLE: "This model has no trained weights yet: train it first."}
    assert str(whole) == "This model has no trained weights yet: train it first."
    assert whole.told("Nothing was exported") == (
        "Nothing was exported: This model has no trained weights yet: train it first."
    )

    fields = configuration.Invalid({"name": "Choose another name.", "seed": "A whole number."})
    assert str(fields) == "name: Choose another name.; seed: A whole number."
    assert fields.told("The model was not created") == (
        "The model was not created:\n  name: Choose another name.\n  seed: A whole number."
    )


def test_every_service_refusal_is_one():
    refusals = (
        configuration.Invalid,
        exports.ExportRefused,
        imports.ImportRefused,
        logs_archive.LogsRefused,
        services.TrackRefused,
        services.VehicleSensorsLocked,
        services.ModelBusy,
        services.EvaluationRefused,
        services.RewardFunctionInvalid,
        SubmissionRefused,
    )
    assert all(issubclass(refusal, Refused) for refusal in refusals)
    track = services.TrackRefused("route", "The route file is empty.")
    assert (track.field, track.message, track.errors) == (
        "route",
        "The route file is empty.",
        {"route": "The route file is empty."},
    )
