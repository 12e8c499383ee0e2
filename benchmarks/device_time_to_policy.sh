#!/bin/bash
# Issue 30 item 6: benchmarks/time_to_policy.py with the lean loop's learner on a GPU
# (--device cuda), side by side with the same runs with it on the CPU, each process pinned to
# two cores of its own (taskset), all at once. What docs/speed.md's "On a GPU" records.
#
#   OUT=<folder> bash benchmarks/device_time_to_policy.sh [MAX_MINUTES] [RUN_TIMEOUT_S] [DEVICE]
#
# Eight runs of the residual recipe with the study's flags: the lean loop on DEVICE and on the
# CPU for training seeds 0, 1000 and 2000, and SB3's PPO on DEVICE and on the CPU for seed 0
# (SKIP_S1000=1, SKIP_SB3=1 leave runs out; SKIP_TEST=1 the GPU test). Needs 16 cores. The
# records, logs and each run's last checked policy (for --of ... --held-out) come back as
# $OUT/all.tgz. On a machine that cannot reach a package index, put the wheels of gymnasium,
# farama-notifications, pettingzoo and stable-baselines3 in .whl/ (they are installed from there).
MAXMIN=${1:-3.5}; TMO=${2:-360}; DEV=${3:-cuda}
O=/tmp/o; mkdir -p $O /tmp/r
exec > >(tee $O/main.log) 2>&1
finish() { tar czf "$OUT/all.tgz" -C / tmp/o $(cd / && ls -d tmp/r/*/check.zip 2>/dev/null); }
trap finish EXIT
if [ -d .whl ]; then
  python3 -m pip install -q --no-index --no-deps --no-compile --no-cache-dir --upgrade --target /tmp/site .whl/*.whl || exit 1
  export PYTHONPATH=/tmp/site:$PWD
fi
export PYTHONUNBUFFERED=1
date -u; nproc; lscpu | grep -E "Model name|Thread|Core|Socket|NUMA node" ; command -v taskset
nvidia-smi --query-gpu=name,memory.total,driver_version --format=csv
python3 -c "import torch,numpy,numba,scipy,gymnasium,pettingzoo,stable_baselines3 as s; print(torch.__version__, torch.cuda.is_available(), numpy.__version__, numba.__version__, scipy.__version__, gymnasium.__version__, s.__version__)"
/usr/bin/time -f "precompile %e s" python3 -m uasep_env.precompile
[ -n "$SKIP_TEST" ] || timeout 120 python3 -m pytest -q -p no:cacheprovider tests/test_ppo_lean.py tests/test_training_args.py -k "gpu or copy or device" 2>&1 | tail -4
F="--n-envs 64 --n-steps 64 --batch-size 6144 --n-epochs 1 --learning-rate 0.0003400372129740376 --torch-threads 2"
pin() { c=$1; shift; if [ "${PIN:-1}" = 1 ] && command -v taskset >/dev/null; then taskset -c "$c" "$@"; else "$@"; fi; }
go() {  # name cores trainer device seed
  pin "$2" timeout "$TMO" python3 benchmarks/time_to_policy.py --recipe residual_apf --trainer "$3" \
    --episodes 400 --max-minutes "$MAXMIN" --check-every 4000000 --run-dir /tmp/r/$1 --out $O/$1.json \
    -- $F --seed "$5" --device "$4" > $O/$1.log 2>&1
  echo "$1 exit $?"
}
pids=()
go lean_gpu_s0 0,1 lean $DEV 0 & pids+=($!); go lean_cpu_s0 2,3 lean cpu 0 & pids+=($!)
[ -n "$SKIP_S1000" ] || { go lean_gpu_s1000 4,5 lean $DEV 1000 & pids+=($!); go lean_cpu_s1000 6,7 lean cpu 1000 & pids+=($!); }
go lean_gpu_s2000 8,9 lean $DEV 2000 & pids+=($!); go lean_cpu_s2000 10,11 lean cpu 2000 & pids+=($!)
[ -n "$SKIP_SB3" ] || { go sb3_gpu_s0 12,13 default $DEV 0 & pids+=($!); go sb3_cpu_s0 14,15 default cpu 0 & pids+=($!); }
wait "${pids[@]}"  # not a bare wait: it would wait for the tee above too
nvidia-smi --query-gpu=name,utilization.gpu,memory.used --format=csv
tail -n 3 $O/*.log
