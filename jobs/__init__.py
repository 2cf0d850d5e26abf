"""What runs on the workers: a training job's trainer (``trainer``, with ``checkpoints``, which
picks its best), its rollout workers (``rollouts``) and an evaluation's run (``evaluation``),
one car or a race of several. Its Celery tasks (``jobs.tasks``) import them when they run, so
the web tier never loads PyTorch or the simulator. They read and write training's rows through
its services, lifecycles and leases; they never import its pages.
"""
