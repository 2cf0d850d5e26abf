"""Services queue tasks by name (common.queueing): every name they send is a task the workers
know, routed to the queue whose workers run it."""

from analysis import services as analysis_services
from console.celery import app
from racing import services as racing_services
from training import services as training_services


def test_every_task_a_service_queues_by_name_is_a_workers_task_on_its_queue():
    app.loader.import_default_modules()  # what a worker imports at its start: every app's tasks
    queued = {
        training_services.TRAIN: "training",
        training_services.EVALUATE: "simulation",
        racing_services.RACE: "simulation",
        analysis_services.RESCORE: "rescoring",
    }
    for name, queue in queued.items():
        assert name in app.tasks, f"no worker knows {name}"
        assert app.amqp.router.route({}, name, (), {})["queue"].name == queue
