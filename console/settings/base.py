"""Settings shared by every environment.

Everything that differs between machines is read through ``console.env.env``; the defaults serve
one machine (SQLite, a local Redis started by ``make run``, files under ``var/``). See
docs/operating.md, "Running on several machines", for the variables that switch to PostgreSQL,
S3 and a shared Redis.

Long because every setting the console reads is declared here once, with the reason for its
default beside it, so that docs/operating.md has one place to agree with.
"""

import sys
from pathlib import Path

import dj_database_url
from celery.schedules import crontab
from redis.asyncio.retry import Retry
from redis.backoff import NoBackoff
from redis.exceptions import ConnectionError as RedisConnectionError

from console.env import env
from console.kept_secrets import kept_secret
from console.private_files import private_dir
from console.sizing import machine_sizing

# OpenVINO (the physical car's download) reports usage to Intel over the network, and writes under
# ~/intel, as soon as it is imported, unless its telemetry package is missing; then it uses its own
# no-op stub. A server does neither: the package is made unimportable in every Django process.
sys.modules.setdefault("openvino_telemetry", None)

BASE_DIR = Path(__file__).resolve().parent.parent.parent
VAR_DIR = env.path("PITLANE_VAR_DIR", BASE_DIR / "var")

DEBUG = env.bool("DJANGO_DEBUG", False)
ALLOWED_HOSTS = env.list("DJANGO_ALLOWED_HOSTS", ["127.0.0.1", "localhost", "[::1]"])
CSRF_TRUSTED_ORIGINS = env.list("DJANGO_CSRF_TRUSTED_ORIGINS", [])

INSTALLED_APPS = [
    "daphne",
    "django.contrib.admin",
    "django.contrib.auth",
    "django.contrib.contenttypes",
    "django.contrib.sessions",
    "django.contrib.messages",
    "whitenoise.runserver_nostatic",
    "django.contrib.staticfiles",
    "django.contrib.humanize",
    "channels",
    "console",
    "training",
    "jobs",
    "archives",
    "racing",
    "analysis",
    "notifications",
    "accounts",
    "ninja",  # its Swagger UI's static files, served as ours
    "api",
]

MIDDLEWARE = [
    "django.middleware.security.SecurityMiddleware",
    "console.staticfiles.StaticFilesMiddleware",  # WhiteNoise, async-capable
    "django.contrib.sessions.middleware.SessionMiddleware",
    "django.middleware.common.CommonMiddleware",
    "django.middleware.csrf.CsrfViewMiddleware",
    "django.contrib.auth.middleware.AuthenticationMiddleware",
    "common.time_zones.TimeZoneMiddleware",
    "django.contrib.messages.middleware.MessageMiddleware",
    "django.middleware.clickjacking.XFrameOptionsMiddleware",
    "common.ratelimits.RetryAfterMiddleware",  # every refusal for a limit says when to retry
]

ROOT_URLCONF = "console.urls"
ASGI_APPLICATION = "console.asgi.application"
WSGI_APPLICATION = "console.wsgi.application"

TEMPLATES = [
    {
        "BACKEND": "django.template.backends.django.DjangoTemplates",
        "DIRS": [BASE_DIR / "templates"],
        "APP_DIRS": True,
        "OPTIONS": {
            "context_processors": [
                "django.template.context_processors.request",
                "django.contrib.auth.context_processors.auth",
                "django.contrib.messages.context_processors.messages",
                "console.context_processors.navigation",
                "common.time_zones.time_zone",
                "notifications.context_processors.bell",
            ],
        },
    },
]

# Database: SQLite under var/ for one machine, PostgreSQL (or any dj-database-url URL) for many.
DATABASE_URL = env.url(
    "DATABASE_URL",
    f"sqlite:///{VAR_DIR / 'db.sqlite3'}",
    schemes=("sqlite", "postgres", "postgresql", "pgsql"),
)
DATABASES = {"default": dj_database_url.parse(DATABASE_URL, conn_max_age=0)}
if DATABASES["default"]["ENGINE"] == "django.db.backends.sqlite3":
    # The web server and the Celery worker write to one file: WAL lets readers work while one
    # writer commits, and IMMEDIATE transactions take the write lock up front instead of failing
    # with "database is locked" halfway through.
    DATABASES["default"]["OPTIONS"] = {
        "init_command": "PRAGMA journal_mode=WAL; PRAGMA synchronous=NORMAL;",
        "transaction_mode": "IMMEDIATE",
        "timeout": 20,
    }
DEFAULT_AUTO_FIELD = "django.db.models.BigAutoField"

AUTH_PASSWORD_VALIDATORS = [
    {"NAME": "django.contrib.auth.password_validation.UserAttributeSimilarityValidator"},
    {"NAME": "django.contrib.auth.password_validation.MinimumLengthValidator"},
    {"NAME": "django.contrib.auth.password_validation.CommonPasswordValidator"},
    {"NAME": "django.contrib.auth.password_validation.NumericPasswordValidator"},
]
LOGIN_URL = "login"
LOGIN_REDIRECT_URL = "home"
LOGOUT_REDIRECT_URL = "home"

LANGUAGE_CODE = "en-us"
# One way to write dates on every page (console/formats/en/formats.py), not Django's "Nov. 26".
FORMAT_MODULE_PATH = ["console.formats"]
TIME_ZONE = env.str("PITLANE_TIME_ZONE", "UTC")
USE_I18N = True
USE_TZ = True

# Redis: Celery's broker, the Channels layer and the cache; a shared Redis for many machines.
# Without REDIS_URL, `make run` starts a private Redis on PITLANE_REDIS_PORT with its data in var/,
# and a password made on first start and kept in var/redis_password (console.kept_secrets): any
# local program could otherwise read the jobs' weights and write the broker's tasks.
REDIS_PORT = env.int("PITLANE_REDIS_PORT", 6391, minimum=1, maximum=65535)
REDIS_PASSWORD = None if env.str("REDIS_URL", "") else kept_secret(VAR_DIR / "redis_password")
REDIS_URL = env.url(
    "REDIS_URL",
    f"redis://:{REDIS_PASSWORD}@127.0.0.1:{REDIS_PORT}/0",
    schemes=("redis", "rediss", "unix"),
)

CHANNEL_LAYERS = {
    "default": {
        "BACKEND": "channels_redis.core.RedisChannelLayer",
        "CONFIG": {
            # redis-py 8 times reads out after 5 s by default, as long as the layer's blocking
            # BZPOPMIN waits: an idle websocket's consumer would die (channels_redis#422).
            # After a Redis restart the layer's pool (channels_redis builds it with
            # ConnectionPool.from_url, whose connections retry nothing: redis-py's
            # AbstractConnection.__init__ gives them Retry(NoBackoff(), 0)) still holds
            # connections to the old server, and the first command on one failed, a websocket
            # handshake with it (500). A connection idle for 10 s is pinged before use, and a
            # command or ping that finds its connection dead drops it and is tried once more on a
            # new one (redis.asyncio.client.Redis.execute_command, Connection.check_health). Once,
            # at once, and not after a timeout: a Redis that is down or silent still fails the
            # consumers, which close their sockets (common.sockets) for the pages to reconnect
            # and catch up.
            "hosts": [
                {
                    "address": REDIS_URL,
                    "socket_timeout": 30,
                    "health_check_interval": 10,
                    "retry": Retry(NoBackoff(), 1, supported_errors=(RedisConnectionError,)),
                }
            ],
            "prefix": "pitlane:asgi",
            # A viewer that falls behind loses old messages instead of growing a backlog.
            "capacity": 100,
            "expiry": 30,
        },
    },
}

CACHES = {
    "default": {
        "BACKEND": "django.core.cache.backends.redis.RedisCache",
        "LOCATION": REDIS_URL,
        "KEY_PREFIX": "pitlane:cache",
    },
}

# Celery: configured from these CELERY_* settings by console/celery.py.
CELERY_BROKER_URL = REDIS_URL
CELERY_TASK_IGNORE_RESULT = True
CELERY_TASK_DEFAULT_QUEUE = "simulation"
CELERY_TASK_ACKS_LATE = True
CELERY_TASK_REJECT_ON_WORKER_LOST = True
CELERY_WORKER_PREFETCH_MULTIPLIER = 1
CELERY_WORKER_HIJACK_ROOT_LOGGER = False
CELERY_BROKER_CONNECTION_RETRY_ON_STARTUP = True
CELERY_WORKER_CONSUMER = "console.celery_consumer:Consumer"  # lives through a Redis restart
CELERY_BROKER_TRANSPORT_OPTIONS = {
    "global_keyprefix": "pitlane:celery:",
    # With late acknowledgement, Redis hands an unacknowledged task to another worker after this
    # long: it must outlast the longest training job (1440 min), so a running job is never
    # delivered twice. A trainer that dies is noticed sooner, by its job's lease.
    "visibility_timeout": 25 * 3600,  # [s]
}
CELERY_TASK_SERIALIZER = "json"
CELERY_ACCEPT_CONTENT = ["json"]
# Rate limits (common.ratelimits; docs/operating.md, "Limits"): a count per period, per racer unless
# said: sign-in per racer name and per address, sign-up per address, password reset requests
# per address and per email address asked for. "import" counts the imports that arrived,
# "import-refused" the attempts that did not (a racer correcting an archive tries again).
PITLANE_RATES = {
    action: env.rate(f"PITLANE_RATE_{action.upper().replace('-', '_')}", default)
    for action, default in {
        "sign-in-account": "10/15m",
        "sign-in-address": "30/15m",
        "sign-up": "5/h",
        "profile-password": "10/15m",
        "validate": "30/10m",
        "import": "10/h",
        "import-refused": "30/h",
        "create": "20/h",
        "evaluate": "30/h",
        "rescore": "20/h",
        "password-reset": "5/h",
        "password-reset-email": "3/h",
        "api": "600/10m",  # per token, every request (docs/api.md)
    }.items()
}
RATELIMIT_USE_CACHE = "default"
# django_ratelimit is not an installed app: it would only add a system check whose list of
# caches (django-redis, not Django's own RedisCache) predates Django's; RedisCache's incr is
# Redis's atomic INCRBY, which the counters need.
RATELIMIT_FAIL_OPEN = True  # a cache that cannot count lets attempts through (and logs it)
# Evaluations and race entries a racer may have waiting or driving at once.
PITLANE_MAX_QUEUED_EVALUATIONS = env.int("PITLANE_MAX_QUEUED_EVALUATIONS", 3, minimum=1)
# Reward validations and imports run in each web process's pool of checkers (training.checkers):
# this many at once, and at most this many more waiting; past that a racer is asked to retry.
PITLANE_CHECKERS = env.int("PITLANE_CHECKERS", 2, minimum=1)
PITLANE_CHECKS_WAITING = env.int("PITLANE_CHECKS_WAITING", 8, minimum=0)
# The largest request body (console.bodylimit): any page, and the model import's archive upload
# (archives.imports.MAX_ARCHIVE, 256 MiB, with room for the form around it).
PITLANE_MAX_BODY = env.int("PITLANE_MAX_BODY", 10 * 2**20, minimum=2**20)  # [bytes]
PITLANE_MAX_IMPORT_BODY = env.int("PITLANE_MAX_IMPORT_BODY", 257 * 2**20, minimum=2**20)  # [bytes]
# Bodies being received by one web process together (console.daphne_body): past it a body over
# 100 kB is refused (503, Retry-After) until others finish; and each body's deadline, from its
# headers: this many seconds, or its size at PITLANE_BODY_RATE if longer.
PITLANE_BODIES_IN_FLIGHT_MAX = env.int("PITLANE_BODIES_IN_FLIGHT_MAX", 2**30, minimum=2**20)
PITLANE_BODY_DEADLINE = env.int("PITLANE_BODY_DEADLINE", 30, minimum=1)  # [s]
PITLANE_BODY_RATE = env.int("PITLANE_BODY_RATE", 512 * 2**10, minimum=2**10)  # [bytes/s]
# All racers' uploads kept for an import's next step (archives.kept_uploads) together: past it
# a new one is refused in words until one is confirmed, cancelled or expires.
PITLANE_KEPT_UPLOADS_MAX = env.int("PITLANE_KEPT_UPLOADS_MAX", 2 * 2**30, minimum=2**20)  # [bytes]
# The queues a complete deployment serves; /healthz reports any that no worker consumes. Each has
# a worker (a pool of processes) of its own, on one machine too (console.supervisor), so that
# no kind of work can take the processes another waits on: trainers never hold the places their
# rollouts need, and re-scorings (a racer's reward function over recorded driving, minutes of
# sandbox calls) never hold those of training, evaluations and races.
PITLANE_QUEUES = ("training", "simulation", "rescoring")
# What `make run` (console.supervisor) starts, from the machine's cores and free memory
# (console.sizing; a variable set wins; its children get the same): jobs training at once, the
# simulation worker's processes (rollouts, evaluations, races), and a trainer's most threads:
# before each update it takes the cores shared among the jobs training then (jobs.trainer's
# share_cores: two trainers with every core each were several times slower than with half).
SIZING = machine_sizing()
PITLANE_TRAINERS = env.int("PITLANE_TRAINERS", SIZING.trainers, minimum=1)
PITLANE_WORKER_CONCURRENCY = env.int("PITLANE_WORKER_CONCURRENCY", SIZING.simulations, minimum=1)
PITLANE_TRAINER_THREADS = env.int("PITLANE_TRAINER_THREADS", SIZING.trainer_threads, minimum=1)
# What a trainer's policy updates compute the features in, the camera's convolutions and the
# middleware (rl.learner.update_precision): "fp32"; "bf16", autocast, the weights, heads, losses
# and optimiser in float32 (log-probabilities within 0.013 of fp32's on the same weights and
# frames, beside PPO's clip of 0.2; on the dev box's 2 AVX-512 BF16 cores a PPO update took
# 10.5 ms a step against 15.0, SAC 80 ms a gradient step against 130); "auto": bf16 where the
# device computes it natively (a GPU from Ampere on, a CPU with AVX-512 BF16 or AMX). fp32 until
# bf16 is shown to learn as well (bench.bench_training --qualify --precision bf16).
PITLANE_TRAINER_PRECISION = env.choice(
    "PITLANE_TRAINER_PRECISION", "fp32", choices=("fp32", "bf16", "auto")
)  # rl.learner.PRECISIONS, not imported here: it would load torch into every process
# A rollout worker silent this long is taken for dead and replaced; a new one may take longer to
# start (torch, the simulator and the sandbox load first).
PITLANE_ROLLOUT_SILENCE = env.int("PITLANE_ROLLOUT_SILENCE", 30, minimum=5)  # [s]
# A trainer renews its job's lease every 3 s, and an evaluation's run its own; a job whose lease
# lapses this long (its training machine died) is taken up by another training worker, from its
# last checkpoint, and an evaluation or race is driven again by another simulation worker.
PITLANE_TRAINER_LEASE = env.int("PITLANE_TRAINER_LEASE", 45, minimum=10)  # [s]
PITLANE_ROLLOUT_STARTUP = env.int("PITLANE_ROLLOUT_STARTUP", 90, minimum=10)  # [s]
# Cars a rollout worker drives together (jobs.rollouts): each step runs the policy once for
# all of them, and a batched forward pass costs far less per car than one per car (on one core of
# the 2-core dev box: 12.6 ms a car at 1, 6.8 at 4, 4.6 at 8; 1.27 at 64 on the GPU box's CPU),
# so a core drives 2.3 to 3 times the steps/s with 8 cars as with 1 (bench.bench_sandbox --cars).
# The same on any machine: the gain is per core, not from more of them. Not more: each car adds
# an environment (about 28 MiB) and an episode in memory, and an iteration is 20 episodes by
# default, which more cars would finish with fewer and fewer of them driving. A SAC worker drives
# one (it wants an episode per update: jobs.rollouts.cars_for). Fewer where memory is short.
PITLANE_CARS_PER_WORKER = env.int("PITLANE_CARS_PER_WORKER", SIZING.cars, minimum=1, maximum=64)
# Where a rollout's cars' policy runs. "auto", "cpu" and "cuda": in the machine's policy server
# (rl.policy_server, one process a machine, started by the first rollout worker that needs it and
# ended once none has for 5 minutes), which answers every sandbox child of every job on the machine
# through shared memory, one batched forward pass a policy for all the children that drive with
# it: on the GPU where PyTorch finds one ("auto"), on the CPU, or on the GPU ("cuda": a job fails
# in words where there is none). One CUDA context for the machine, not one a worker (decision
# 0006's 15 contexts took turns on the GPU), and no child loads PyTorch. "child": the policy in
# each sandbox child, as before issue 56 (docs/decisions/0011-one-policy-server-a-machine.md).
PITLANE_ROLLOUT_DEVICE = env.choice(
    "PITLANE_ROLLOUT_DEVICE", "auto", choices=("auto", "cpu", "cuda", "child")
)
# Where the machine's rollout workers reach its policy server: a Unix socket (at most 107 bytes
# of path), under var/, which only its owner may enter.
PITLANE_POLICY_SOCKET = env.path("PITLANE_POLICY_SOCKET", VAR_DIR / "policy.sock")
# Where a machine's rollout workers share the policy weights they drive with (rl.weights_cache):
# Redis sends each iteration's weights once per machine, not once per worker. On disk under var/
# rather than in /dev/shm: a container's /dev/shm is often 64 MiB, less than a 5-layer model's
# 230 MB, and the page cache serves a file just written from memory all the same.
PITLANE_WEIGHTS_CACHE = env.path("PITLANE_WEIGHTS_CACHE", VAR_DIR / "weights")
# An evaluation or a race that someone watches keeps to this many times real time (1: as the
# DeepRacer console shows it); nobody watching, it runs as fast as it can.
PITLANE_WATCHED_SPEEDUP = env.int("PITLANE_WATCHED_SPEEDUP", 1, minimum=1, maximum=20)
CELERY_TASK_ROUTES = {
    "training.train": {"queue": "training"},  # the trainer: a GPU machine, where there is one
    "training.rollout": {"queue": "simulation"},  # rollouts: any CPU machine
    "training.evaluate": {"queue": "simulation"},  # evaluations: no racer code
    "training.racing_line": {"queue": "simulation"},  # a track's racing line: seconds of CPU
    "racing.race": {"queue": "simulation"},  # a race submission is an evaluation
    "racing.promote": {"queue": "simulation"},
    "analysis.rescore": {"queue": "rescoring"},  # a racer's reward function, in the sandbox
    "accounts.password_reset_email": {"queue": "simulation"},  # off the request: see its task
}
# Celery beat (run inside the worker by `make run`; one `celery -A console beat` when scaled out).
CELERY_BEAT_SCHEDULE = {
    "promote-to-pro": {  # the top 10% of last month's Open time trials move up to Pro
        "task": "racing.promote",
        "schedule": crontab(minute=15, hour=0, day_of_month=1),
    },
}
CELERY_BEAT_SCHEDULE_FILENAME = str(VAR_DIR / "celerybeat-schedule")
CELERY_TIMEZONE = TIME_ZONE

# Files: static assets are served by WhiteNoise; artifacts go through Django's storage API, to local
# disk under var/media/ by default or to an S3 bucket (or an S3-compatible store) when one is named.
STATIC_URL = "/static/"
STATIC_ROOT = VAR_DIR / "static"
STATICFILES_DIRS = [BASE_DIR / "static"]
MEDIA_ROOT = VAR_DIR / "media"
MEDIA_URL = "/media/"
# Uploads and what is stored from them are their owner's alone, as all of var/ is
# (console.private_files); an upload over 2.5 MiB is spooled under var/, where a web server killed
# during it leaves its file for the workers' housekeeping to delete, not in /tmp for ever.
FILE_UPLOAD_PERMISSIONS = 0o600
FILE_UPLOAD_DIRECTORY_PERMISSIONS = 0o700
FILE_UPLOAD_TEMP_DIR = str(private_dir(private_dir(VAR_DIR) / "uploads-tmp"))

S3_BUCKET = env.str("PITLANE_S3_BUCKET", "")
if S3_BUCKET:
    _artifact_storage = {
        "BACKEND": "storages.backends.s3.S3Storage",
        "OPTIONS": {
            "bucket_name": S3_BUCKET,
            "region_name": env.str("PITLANE_S3_REGION", "") or None,
            "endpoint_url": env.url("PITLANE_S3_ENDPOINT_URL", "", schemes=("http", "https"))
            or None,
            # Credentials come from boto3's own chain: AWS_ACCESS_KEY_ID/AWS_SECRET_ACCESS_KEY,
            # a profile, or an instance role.
            "default_acl": None,
            "querystring_auth": True,
            "querystring_expire": 300,  # [s] a download link's life
            "signature_version": "s3v4",
            "file_overwrite": True,
        },
    }
else:
    _artifact_storage = {
        "BACKEND": "django.core.files.storage.FileSystemStorage",
        "OPTIONS": {"location": MEDIA_ROOT, "base_url": MEDIA_URL},
    }
# DeepRacer for Cloud's bucket, which staff import models from (archives.drfc_bucket: the
# console's import page, `manage.py importmodel s3://...`, the API): its S3 API (DRfC's MinIO by
# default) and keys; boto3's own chain where the keys are not given.
PITLANE_DRFC_S3 = {
    "endpoint_url": env.url("PITLANE_DRFC_S3_ENDPOINT_URL", "", schemes=("http", "https")) or None,
    "region_name": env.str("PITLANE_DRFC_S3_REGION", "") or None,
    "aws_access_key_id": env.str("PITLANE_DRFC_S3_ACCESS_KEY_ID", "") or None,
    "aws_secret_access_key": env.str("PITLANE_DRFC_S3_SECRET_ACCESS_KEY", "") or None,
}
STORAGES = {
    "default": _artifact_storage,
    "staticfiles": {"BACKEND": "whitenoise.storage.CompressedManifestStaticFilesStorage"},
}

# Email: notifications (a training's, an evaluation's or a race's end) also go out by email when
# PITLANE_EMAIL_URL names a server; without it the bell in the console is all there is.
_email_server = env.email("PITLANE_EMAIL_URL")
PITLANE_EMAIL_NOTIFICATIONS = _email_server is not None
# A racer who forgot their password gets a reset link by email only where there is a server;
# without one, the "Forgot your password?" page tells them to ask league staff (the admin).
PITLANE_PASSWORD_RESET_BY_EMAIL = _email_server is not None
PASSWORD_RESET_TIMEOUT = 2 * 3600  # [s] a reset link works this long, and once
if _email_server is not None:
    EMAIL_BACKEND = _email_server.backend
    EMAIL_HOST, EMAIL_PORT = _email_server.host, _email_server.port
    EMAIL_HOST_USER, EMAIL_HOST_PASSWORD = _email_server.user, _email_server.password
    EMAIL_USE_TLS, EMAIL_USE_SSL = _email_server.use_tls, _email_server.use_ssl
    EMAIL_TIMEOUT = 20  # [s]
DEFAULT_FROM_EMAIL = env.str("PITLANE_EMAIL_FROM", "Pitlane <pitlane@localhost>")
# Where racers reach this console: the links in emails.
PITLANE_SITE_URL = env.url("PITLANE_SITE_URL", "http://127.0.0.1:8000", schemes=("http", "https"))

LOGGING = {
    "version": 1,
    "disable_existing_loggers": False,
    "formatters": {
        "plain": {"format": "%(asctime)s %(levelname)s %(name)s: %(message)s"},
    },
    "handlers": {
        "console": {"class": "logging.StreamHandler", "formatter": "plain"},
    },
    "root": {"handlers": ["console"], "level": env.str("PITLANE_LOG_LEVEL", "INFO")},
    "loggers": {
        # Daphne logs every request at INFO; keep the terminal for what matters.
        "django.channels.server": {"level": "WARNING"},
    },
}
CSRF_FAILURE_VIEW = "console.views.csrf_failure"
