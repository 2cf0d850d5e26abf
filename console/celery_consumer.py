"""The Celery worker's consumer, made to live through a restart of its broker (Redis).

When the consumer loses a broker it was connected to, Celery collects the broken connection
(``Connection.collect``), which lets go of its transport: ``transport.client = None``
(kombu/connection.py:427-430). The channels that collect could not close still refer to that
transport, and with tasks in progress under late acknowledgement (every rollout and training
task) there is one: closing it tries to give the unacknowledged tasks back to Redis, which is
down. From then on anything those channels do reads the broker's address from the transport
(kombu/transport/redis.py:1959, ``self.connection.client.hostname``) and raises
``AttributeError``, which neither Celery nor kombu expect:
- Celery 5.7.0 closes the collected connection again (celery/worker/consumer/consumer.py:487);
- a task that was running when Redis went away and ends after the reconnect is acknowledged on
  its old channel (kombu/message.py:126).
Either stops the worker with "Unrecoverable error". This consumer gives the transport its
broker's address back once collect is done, so those channels fail as kombu expects, with a
connection error while Redis is down (ignored) or by reaching the new Redis, and the consumer
reconnects: tasks in progress carry on, and those a restarted Redis lost are sent again by their
jobs (training.leases).
"""

from __future__ import annotations

import functools

from celery.worker.consumer import Consumer as CeleryConsumer


class Consumer(CeleryConsumer):
    def on_connection_error_after_connected(self, exc):
        if self.connection is not None:
            self.connection.collect = _keeping_the_address(
                self.connection.collect, self.connection.transport
            )
        super().on_connection_error_after_connected(exc)


def _keeping_the_address(collect, transport):
    broker = transport.client

    @functools.wraps(collect)
    def collecting(*args, **kwargs):
        try:
            collect(*args, **kwargs)
        finally:
            transport.client = broker

    return collecting
