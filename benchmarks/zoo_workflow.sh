#!/usr/bin/env bash
# The rl-zoo user's workflow from a built wheel, for every sb3-es algorithm (tiny budgets, a few minutes):
# build the wheel, install it with [zoo] into a virtual environment, then, from a folder outside the source
# tree, run train, enjoy, record_video and -optimize (2 trials) for every key of sb3_es.zoo.ALGOS, then
# record_training, plot_train and all_plots. (rl-zoo's plot_from_file needs two runs or more per algorithm:
# tests/test_zoo.py runs it on benchmarks/compare.py's output.)
#
# usage: benchmarks/zoo_workflow.sh [WORK_DIR]        (default WORK_DIR: a new temporary folder)
#   VENV=/path/to/venv   install the wheel into this existing venv (e.g. a copy of a dev venv, to reuse its
#                        torch and MuJoCo); default: a new venv in WORK_DIR, with pip resolving [zoo] and the
#                        pins of constraints.txt from the package index.
#   PYTHON=python3       interpreter that builds the wheel and creates the venv.
set -euo pipefail

ROOT="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
WORK="${1:-$(mktemp -d -t sb3_es_zoo_workflow.XXXXXX)}"
PYTHON="${PYTHON:-python3}"
mkdir -p "$WORK"
WORK="$(cd "$WORK" && pwd)"
START=$SECONDS
step() { printf '\n=== [%4ds] %s\n' $((SECONDS - START)) "$*"; }

step "build the wheel from $ROOT"
rm -rf "$WORK/dist" "$WORK/src"
mkdir -p "$WORK/src"
# build from a copy, so that the build leaves nothing in the source tree
cp -r "$ROOT/sb3_es" "$ROOT/pyproject.toml" "$ROOT/README.md" "$ROOT/LICENSE" "$WORK/src/"
find "$WORK/src" -name __pycache__ -prune -exec rm -rf {} +
"$PYTHON" -m pip wheel --no-deps --no-build-isolation -q "$WORK/src" -w "$WORK/dist"
WHEEL="$(ls "$WORK"/dist/sb3_es-*.whl)"
echo "$WHEEL"

if [ -z "${VENV:-}" ]; then
    VENV="$WORK/venv"
    step "new venv $VENV"
    "$PYTHON" -m venv "$VENV"
fi
PY="$VENV/bin/python"
step "pip install ${WHEEL##*/}[zoo] into $VENV"
"$PY" -m pip install -q -c "$ROOT/constraints.txt" "${WHEEL}[zoo]"
# the installed package, not the source tree, must be the one imported
mkdir -p "$WORK/run"
cd "$WORK/run"
"$PY" -c "import sb3_es, sys; assert '$ROOT' not in sb3_es.__file__, sb3_es.__file__; print('sb3_es from', sb3_es.__file__)"
KEYS="$("$PY" -c 'from sb3_es.zoo import ALGOS; print(*ALGOS)')"
echo "sb3-es keys: $KEYS"

zoo() { nice -n 19 "$PY" -m sb3_es.zoo "$@"; }
small() {  # -params that keep one generation (update) small on Pendulum-v1
    case "$1" in
        ars_es) echo "n_delta:2" ;;
        openes | cmaes) echo "population_size:4" ;;
        reinforce) echo "n_episodes:2" ;;
        *) echo "n_envs:2" ;;
    esac
}

for key in $KEYS; do
    step "$key: train (Pendulum-v1, 1,600 steps, 2 evaluations of 2 episodes)"
    zoo train --algo "$key" --env Pendulum-v1 -n 1600 --seed 0 -tb tb --eval-freq 800 --eval-episodes 2 \
        --verbose 0 -params $(small "$key")
    step "$key: enjoy"
    zoo enjoy --algo "$key" --env Pendulum-v1 --no-render -n 200 | tail -n 3
    step "$key: record_video"
    zoo record_video --algo "$key" --env Pendulum-v1 -n 100 -o "videos/$key" 2>&1 | grep -v "frame_index" | tail -n 1
    ls -la "videos/$key"
    step "$key: -optimize, 2 trials"
    env_id=CartPole-v1
    extra=()
    if [ "$key" = reinforce ]; then env_id=Pendulum-v1; extra=(-params n_episodes:2); fi
    zoo train --algo "$key" --env "$env_id" -optimize --n-trials 2 -n 400 --n-evaluations 2 --eval-episodes 1 \
        --n-startup-trials 1 --no-optim-plots --seed 0 --verbose 0 -f optimize "${extra[@]}" 2>&1 | tail -n 8
    ls optimize/"$key"/report_*.csv
done

FIRST="${KEYS%% *}"
step "$FIRST: record_training (the sb3-es console script: sb3-es is python -m sb3_es.zoo)"
nice -n 19 "$VENV/bin/sb3-es" record_training --algo "$FIRST" --env Pendulum-v1 -n 100 2>&1 | grep -v "frame_index" | tail -n 2
ls -la "logs/$FIRST/Pendulum-v1_1/videos/training.mp4"
step "plot_train, all_plots"
for key in $KEYS; do
    MPLBACKEND=Agg zoo plot_train -a "$key" -e Pendulum-v1 -f logs -w 4
done
MPLBACKEND=Agg zoo all_plots -a $KEYS -e Pendulum-v1 -f logs --no-display -o all_plots
ls -la all_plots.pkl
step "done: train, enjoy, record_video and -optimize for $KEYS; record_training, plot_train and all_plots;
from $WHEEL in $VENV; outputs in $WORK/run"
