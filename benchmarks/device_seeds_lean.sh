#!/bin/bash
# The training stage of the lean residual report (baselines/results/seeds_residual_apf_lean.*)
# on a machine with at least six cores: the three runs `train/seeds.py --parallel 1` would
# start one after the other (the same commands and flags), side by side, each pinned to two
# cores of its own (taskset), as a 2-core machine would run each alone.
#
#   OUT=<folder> bash benchmarks/device_seeds_lean.sh [MAX_MINUTES]
#
# Then put the returned folders seed_0..seed_2 and their logs in runs/seeds_residual_lean/
# and run the train/seeds.py command of docs/protocol.md: it finds the trained seeds (their
# policy.zip and validation.json) and goes on with the selection, the held-out games and the
# report. On a machine that cannot reach a package index, put the wheels of gymnasium,
# farama-notifications, pettingzoo and stable-baselines3 in .whl/ (installed from there).
MAXMIN=${1:-7}
O=/tmp/o; mkdir -p $O
exec > >(tee $O/main.log) 2>&1
finish() { tar czf "$OUT/runs.tgz" -C /tmp/o .; }
trap finish EXIT
if [ -d .whl ]; then
  python3 -m pip install -q --no-index --no-deps --no-compile --no-cache-dir --upgrade --target /tmp/site .whl/*.whl || exit 1
  export PYTHONPATH=/tmp/site:$PWD
fi
export PYTHONUNBUFFERED=1
date -u; nproc; lscpu | grep -E "Model name"
python3 -c "import torch,numpy,numba,stable_baselines3 as s; print(torch.__version__, numpy.__version__, numba.__version__, s.__version__)"
/usr/bin/time -f "precompile %e s" python3 -m uasep_env.precompile
F="--trainer lean --n-envs 64 --n-steps 64 --batch-size 6144 --n-epochs 1 --learning-rate 0.0003400372129740376 --torch-threads 2 --checkpoint-every 4000000 --max-minutes $MAXMIN"
pids=()
for k in 0 1 2; do
  # As train/seeds.py starts seed k: its out-dir and seed, one process on its cores.
  UASEP_WORKERS=1 taskset -c $((2*k)),$((2*k+1)) python3 train/ppo_residual_apf.py \
    --out-dir $O/seed_$k --seed $((1000*k)) --torch-threads 1 --no-progress $F > $O/seed_$k.log 2>&1 &
  pids+=($!)
done
wait "${pids[@]}"  # not a bare wait: it would wait for the tee above too
for k in 0 1 2; do echo "seed $k"; tail -n 4 $O/seed_$k.log; ls $O/seed_$k/checkpoints | tr '\n' ' '; echo; done
date -u
