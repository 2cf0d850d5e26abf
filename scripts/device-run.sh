#!/bin/sh
# What a session lent a GPU runs there, in one call a part (run with carry ["var/device"],
# timeout_s 540), after `make device-bundle` has filled var/device/ here:
#
#   sh scripts/device-run.sh update     # the policy update alone, PPO and SAC, and the GPU tests
#   sh scripts/device-run.sh pipeline 1 # one job's real pipeline for 5 minutes, its time split
#   sh scripts/device-run.sh pipeline 4 # four jobs at once, 5 minutes (then 8, if time is left)
#   sh scripts/device-run.sh stub 1     # one job with the update stubbed out: the ceiling
#
# It installs the bundle's wheels and Redis under /tmp (never over /), then measures, each step
# under its own timeout so that one failing or running long still leaves the others' figures:
#   update: the policy update alone on the GPU, PPO and SAC, with each variant
#     (bench_training --update), then the GPU-only tests (4 of them skip without CUDA)
#   pipeline N / stub N: training throughput without the web tier, N jobs at once for 5
#     minutes (bench_pipeline), every rollout's cars served by the machine's policy server on
#     the GPU; it prints each job's steps/s and where its iterations' time went
# under bench/pipeline_settings.py: Daphne, the web tier's server, is not carried.
# Each step's output lands in $OUT (the device tool brings it back) as well as on stdout.
set -u
D=/tmp/pitlane-debs
for f in var/device/debs/*.deb; do dpkg -x "$f" "$D"; done
echo "$D/usr/lib/x86_64-linux-gnu" >/etc/ld.so.conf.d/zz-pitlane.conf
ldconfig
python3 -m pip install -q --no-index --no-deps --no-compile --target /tmp/site var/device/wheels/*.whl
# after the image's own packages: its PyTorch, OpenCV and NumPy stay the ones it was built with
echo /tmp/site >"$(python3 -c 'import site; print(site.getsitepackages()[0])')/pitlane.pth"
export PATH="$D/usr/bin:$PATH" PYTHONUNBUFFERED=1 DJANGO_SETTINGS_MODULE=bench.pipeline_settings
OUT=${OUT:-var/device/out}
mkdir -p "$OUT"
nvidia-smi -L
python3 -c 'import torch; print("PyTorch", torch.__version__, torch.cuda.get_device_name())'

PART=${1:-update}
JOBS=${2:-1}
case "$PART" in
update)
	timeout 75 python3 -m bench.bench_training --update --device cuda --steps 2000 2>&1 |
		tee "$OUT/update-ppo.txt"
	timeout 45 python3 -m bench.bench_training --update --device cuda --algorithm sac \
		--steps 500 2>&1 | tee "$OUT/update-sac.txt"
	PYTHONPATH=/tmp/site timeout 120 python3 -m pytest --ds bench.pipeline_settings -q -rs \
		-p no:cacheprovider tests/rl/test_learner.py tests/sandbox/test_served_policy.py \
		-k "gpu or cuda" 2>&1 | tail -25 | tee "$OUT/gpu-tests.txt"
	;;
pipeline | stub)
	UPDATE=real
	[ "$PART" = stub ] && UPDATE=stub
	timeout 500 python3 -m bench.bench_pipeline --minutes 5 --jobs "$JOBS" --update "$UPDATE" \
		2>&1 | tee "$OUT/$PART-$JOBS.txt"
	;;
*)
	echo "usage: sh scripts/device-run.sh update | pipeline N | stub N" >&2
	exit 2
	;;
esac
