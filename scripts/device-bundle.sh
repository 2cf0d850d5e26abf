#!/bin/sh
# What the device machine needs to run bench/bench_pipeline.py, fetched here into var/device/:
#   wheels/  the cp312 manylinux wheels of the packages its image lacks (its python3 is 3.12 with
#            PyTorch, OpenCV, NumPy, SciPy, msgpack, safetensors, cloudpickle, PyYAML, click,
#            python-dateutil already there; /work/.library/device/KINDS.md lists them)
#   debs/    Debian's redis-server and the libraries it (and pyseccomp) load, unpacked there
#            under /tmp, never over /
# then prints their size (a device call carries 64 MiB with the project's code) and the one
# command a session with a GPU runs. PyBullet is not among them (no cp312 wheel): the pipeline's
# model is a time trial with the camera, which needs no collision world.
#
#   scripts/device-bundle.sh           fetch (again) and print the command
#   make device-bundle                 the same
set -eu
cd "$(dirname "$0")/.."
OUT=var/device
PYTHON=${PYTHON:-.venv/bin/python}

# The versions requirements/run.txt pins; tzdata (Celery's zone names where the image has no
# /usr/share/zoneinfo) is the one not there. No Daphne: the bench runs without the web tier.
PACKAGES="Django asgiref sqlparse celery kombu billiard vine amqp click-didyoumean click-plugins
click-repl prompt_toolkit wcwidth tzlocal channels channels_redis redis dj-database-url
whitenoise django-ratelimit gymnasium Farama-Notifications stable_baselines3 pyseccomp shapely
google-crc32c"
# and for the GPU-only tests, the versions requirements/test.txt pins (the image's pytest may be
# older than pytest-asyncio takes; scripts/device-run.sh puts these first on the tests' path)
TEST_PACKAGES="pytest pytest-django pytest-asyncio pytest-timeout pluggy iniconfig deepracer-utils boto3
botocore s3transfer jmespath"
# libssl3 and libsystemd0, which redis-tools also needs, are in the image (its Python and apt
# load them); libatomic1 travels in case its compilers did not bring it.
DEBS="redis-server redis-tools libjemalloc2 liblzf1 libatomic1 libseccomp2"

pinned() {  # pinned PACKAGE [FILE]
	file=${2:-requirements/run.txt}
	name=$(echo "$1" | tr 'A-Z_' 'a-z-')
	line=$(grep -i "^$1==" "$file" || tr 'A-Z_' 'a-z-' <"$file" | grep "^$name==" || true)
	[ -n "$line" ] || { echo "$1 is not pinned in $file" >&2; exit 1; }
	echo "$line"
}

rm -rf "$OUT/wheels" "$OUT/debs"
mkdir -p "$OUT/wheels" "$OUT/debs"
specs="tzdata==2026.2"
for package in $PACKAGES; do specs="$specs $(pinned "$package")"; done
for package in $TEST_PACKAGES; do specs="$specs $(pinned "$package" requirements/test.txt)"; done
# shellcheck disable=SC2086  # one argument per requirement
"$PYTHON" -m pip download --quiet --no-deps --only-binary=:all: --python-version 3.12 \
	--implementation cp --abi cp312 --platform manylinux_2_28_x86_64 \
	--platform manylinux_2_17_x86_64 --platform manylinux2014_x86_64 --platform any \
	-d "$OUT/wheels" $specs
(cd "$OUT/debs" && apt-get download $DEBS >/dev/null)

carried=$(du -sb "$OUT" | cut -f1)
tracked=$(git ls-files -z | du -cb --files0-from=- | tail -1 | cut -f1)  # one total: xargs may split it
echo "var/device: $(du -sh "$OUT/wheels" | cut -f1) of wheels ($(ls "$OUT/wheels" | wc -l)), \
$(du -sh "$OUT/debs" | cut -f1) of Debian packages; with the project's tracked files \
$(((carried + tracked) / 1048576)) MiB of the 64 MiB a call carries."
[ $((carried + tracked)) -lt $((64 * 1048576)) ] || { echo "That is too much for one call." >&2; exit 1; }
echo
echo 'A session with a GPU runs `sh scripts/device-run.sh` there, with carry ["var/device"] and'
echo 'timeout_s 540 (what it measures: the script says).'
