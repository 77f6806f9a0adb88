#!/usr/bin/env bash
# The rl-zoo user's workflow from a built wheel, for every sb3-es algorithm (tiny budgets; about 10 minutes on
# one core once the packages are installed):
#   1. build the wheel from a copy of the source tree and install it with [zoo] into a new virtual environment;
#   2. from a folder outside the source tree, for every key of sb3_es.zoo.ALGOS: train (Pendulum-v1, the
#      packaged file: its Pendulum-v1 entry, or its 'default' entry where it has none, as the log line says), enjoy,
#      record_video, and train -optimize (2 trials, CartPole-v1, which has no entry in most files: the 'default'
#      fallback line is checked);
#   3. record_training (through the sb3-es console script), a second seed per key, plot_train, all_plots and
#      plot_from_file (rliable's intervals and IQM; it needs two runs per algorithm).
# Any failure stops the script with a non-zero exit status; the last lines sum up what ran and where.
#
# usage: benchmarks/zoo_workflow.sh [WORK_DIR]        (default WORK_DIR: a new temporary folder)
#   PYTHON=python3      interpreter that creates the venv. The wheel is built by the venv's pip in an isolated build
#                       environment (setuptools from the package index, as in a release build), then installed with
#                       pip resolving [zoo] and the pins of constraints.txt from the package index.
#   VENV=/path/to/venv  use this existing venv instead of a new one (it replaces the sb3_es installed there): the
#                       route for a machine without a package index, with a venv that already has the [zoo]
#                       dependencies (pip finds them satisfied and downloads nothing) and setuptools>=77 (the
#                       wheel is then built without build isolation).
set -euo pipefail

ROOT="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
WORK="${1:-$(mktemp -d -t sb3_es_zoo_workflow.XXXXXX)}"
PYTHON="${PYTHON:-python3}"
mkdir -p "$WORK"
WORK="$(cd "$WORK" && pwd)"
START=$SECONDS
SUMMARY=()
step() { printf '\n=== [%4ds] %s\n' $((SECONDS - START)) "$*"; }
# ran KEY COMMAND SECONDS: one line of the final summary
ran() { SUMMARY+=("$(printf '%-10s %-16s %4ss' "$1" "$2" "$3")"); }
fail() { echo "FAILED: $*" >&2; exit 1; }

if [ -z "${VENV:-}" ]; then
    VENV="$WORK/venv"
    step "new venv $VENV ($("$PYTHON" --version))"
    rm -rf "$VENV"
    "$PYTHON" -m venv "$VENV"
    ISOLATION=()
else
    ISOLATION=(--no-build-isolation)
fi
PY="$VENV/bin/python"

step "build the wheel from $ROOT"
rm -rf "$WORK/dist" "$WORK/src"
mkdir -p "$WORK/src"
# build from a copy, so that the build leaves nothing in the source tree
cp -r "$ROOT/sb3_es" "$ROOT/pyproject.toml" "$ROOT/README.md" "$ROOT/LICENSE" "$WORK/src/"
find "$WORK/src" -name __pycache__ -prune -exec rm -rf {} +
"$PY" -m pip wheel --no-deps "${ISOLATION[@]}" -q "$WORK/src" -w "$WORK/dist"
WHEEL="$(ls "$WORK"/dist/sb3_es-*.whl)"
echo "$WHEEL"
"$PY" -c "import sys, zipfile; names = zipfile.ZipFile(sys.argv[1]).namelist(); \
print(*sorted(n for n in names if n.startswith('sb3_es/hyperparams/')), sep='\n')" "$WHEEL"

step "pip install ${WHEEL##*/}[zoo] into $VENV"
"$PY" -m pip install -q --force-reinstall --no-deps "$WHEEL"  # replaces an sb3_es already there (VENV=...)
"$PY" -m pip install -q -c "$ROOT/constraints.txt" "${WHEEL}[zoo]"
"$PY" -m pip check
# the installed package, not the source tree, must be the one imported
mkdir -p "$WORK/run"
cd "$WORK/run"
SITE="$("$PY" -c 'import sb3_es, os; print(os.path.dirname(os.path.realpath(sb3_es.__file__)))')"
case "$SITE" in "$ROOT"*) fail "sb3_es imported from the source tree: $SITE" ;; esac
echo "sb3_es from $SITE"
KEYS="$("$PY" -c 'from sb3_es.zoo import ALGOS; print(*ALGOS)')"
echo "sb3-es keys: $KEYS"

zoo() { nice -n 19 "$PY" -m sb3_es.zoo "$@"; }
small() {  # -params that keep one generation (update) small on Pendulum-v1: 800 env steps (REINFORCE: 400)
    case "$1" in
        ars_es) echo "n_delta:2 n_top:2" ;;  # n_top: the Pendulum-v1 entry's (4) is above n_delta 2
        reinforce) echo "n_episodes:2" ;;
        *) echo "population_size:4" ;;
    esac
}
train() {  # train KEY SEED: Pendulum-v1, 1,600 steps, evaluations at 800 and 1,600 (2 episodes each)
    zoo train --algo "$1" --env Pendulum-v1 -n 1600 --seed "$2" -tb tb --eval-freq 800 --eval-episodes 2 \
        --verbose 0 --num-threads 1 -params $(small "$1") > "train-$1-$2.log" 2>&1 || { cat "train-$1-$2.log"; exit 1; }
    # the packaged file of the installed wheel, and the entry used: Pendulum-v1's, or 'default' (a file without a
    # Pendulum-v1 entry: the ones that failed verification were removed)
    grep -E "sb3-es: ($1 on Pendulum-v1: hyperparameters from the Pendulum-v1 entry of $SITE/hyperparams/$1\.yml|\
$SITE/hyperparams/$1\.yml has no Pendulum-v1 entry: $1 trains with its 'default' entry)" "train-$1-$2.log" \
        || fail "train $1: no line naming the packaged file and its entry"
    tail -n 4 "train-$1-$2.log"
}

for key in $KEYS; do
    step "$key: train (Pendulum-v1, 1,600 steps, 2 evaluations of 2 episodes)"
    t=$SECONDS
    train "$key" 0
    ran "$key" train $((SECONDS - t))

    step "$key: enjoy"
    t=$SECONDS
    zoo enjoy --algo "$key" --env Pendulum-v1 --no-render -n 200 | tail -n 3
    ran "$key" enjoy $((SECONDS - t))

    step "$key: record_video"
    t=$SECONDS
    zoo record_video --algo "$key" --env Pendulum-v1 -n 100 -o "videos/$key" 2>&1 | grep -v "frame_index" | tail -n 1
    ls -la "videos/$key"/*.mp4
    ran "$key" record_video $((SECONDS - t))

    step "$key: -optimize, 2 trials"
    t=$SECONDS
    env_id=CartPole-v1
    extra=()
    if [ "$key" = reinforce ]; then env_id=Pendulum-v1; extra=(-params n_episodes:2); fi
    zoo train --algo "$key" --env "$env_id" -optimize --n-trials 2 -n 400 --n-evaluations 2 --eval-episodes 1 \
        --n-startup-trials 1 --no-optim-plots --seed 0 --verbose 0 --num-threads 1 -f optimize "${extra[@]}" \
        > "optimize-$key.log" 2>&1 || { cat "optimize-$key.log"; exit 1; }
    # an env without an entry in the file trains with its 'default' entry, and the log says so
    grep -E "sb3-es: .*(has no $env_id entry: $key trains with its 'default' entry|$key on $env_id: hyperparameters from)" \
        "optimize-$key.log" || fail "optimize $key: no line saying which entry of the packaged file is used"
    grep -E "Number of finished trials|Best trial|Value" "optimize-$key.log"
    report="$(ls optimize/"$key"/report_*.csv)"
    [ "$(wc -l < "$report")" -eq 3 ] || fail "$report: expected a header and 2 trials"
    echo "$report"
    ran "$key" "-optimize" $((SECONDS - t))
done

FIRST="${KEYS%% *}"
step "$FIRST: record_training (the sb3-es console script: sb3-es COMMAND is python -m sb3_es.zoo COMMAND)"
t=$SECONDS
nice -n 19 "$VENV/bin/sb3-es" record_training --algo "$FIRST" --env Pendulum-v1 -n 100 2>&1 | grep -v "frame_index" | tail -n 2
ls -la "logs/$FIRST/Pendulum-v1_1/videos/training.mp4"
ran "$FIRST" record_training $((SECONDS - t))

step "a second seed per key (plot_from_file needs two runs per algorithm)"
for key in $KEYS; do
    t=$SECONDS
    train "$key" 1
    ran "$key" "train (seed 1)" $((SECONDS - t))
done

step "plot_train, all_plots, plot_from_file"
t=$SECONDS
for key in $KEYS; do
    MPLBACKEND=Agg zoo plot_train -a "$key" -e Pendulum-v1 -f logs -w 4
done
ran all plot_train $((SECONDS - t))
t=$SECONDS
MPLBACKEND=Agg zoo all_plots -a $KEYS -e Pendulum-v1 -f logs --no-display -o all_plots | tee all_plots.log
grep -q "0.0 +/- 0.0" all_plots.log && fail "all_plots: a run without evaluations"
ls -la all_plots.pkl
ran all all_plots $((SECONDS - t))
t=$SECONDS
MPLBACKEND=Agg zoo plot_from_file -i all_plots.pkl --rliable --iqm -o rliable.png --format png 2>&1 | tee plot_from_file.log \
    | grep -v "not found for normalizing"
grep -q "Computing bootstrap CI" plot_from_file.log || fail "plot_from_file: no rliable intervals"
ls -la rliable.png
ran all plot_from_file $((SECONDS - t))

step "done in $((SECONDS - START)) s: ${WHEEL##*/} in $VENV, outputs in $WORK/run"
printf '%s\n' "${SUMMARY[@]}"
echo "ok: train, enjoy, record_video and -optimize for $KEYS; record_training, plot_train, all_plots, plot_from_file"
