#!/usr/bin/env bash
# hintsjax on a GPU machine that has jax (CUDA) but no internet, as docs/gpu.md describes: carry
# the missing packages as wheels, install them beside the machine's own, run, and watch a run
# started detached. Python 3.12, x86-64 (the wheels' tags; change PY and PLATFORMS for others).
#
#   bash experiments/offline_gpu.sh wheels            # here, with internet: .whl/ (mujoco alone, 27 MB), .whl2/
#                                                     #   (mjx, hydra, this project...), .whl3/ (Playground and
#                                                     #   Brax, 14 MB), .wp/warp.part.0[0-5] (warp-lang in 6 parts)
#   bash experiments/offline_gpu.sh calls             # here: the device calls that carry them, in order (each
#                                                     #   checked against the 64 MiB a call takes with the tree)
#   bash experiments/offline_gpu.sh install [DIR]     # there, in the repo root: DIR's wheels (.whl2) into /tmp/site
#                                                     #   (the calls' second installs .whl2's and .whl3's together)
#   bash experiments/offline_gpu.sh warp              # there: keep the .wp parts carried so far; all 6 in: install
#   bash experiments/offline_gpu.sh poll SECONDS MARK # there: wait up to SECONDS or until /tmp/MARK exists, show
#                                                     #   the logs' last lines (/tmp/logs/*.log) and pack the runs'
#                                                     #   small files (/tmp/r: csv, json, jsonl, yaml) into $OUT/runs.tgz
# Then run with PYTHONPATH=/tmp/site from a folder outside the repo (the installed hintsjax, not the source tree):
#   cd /tmp && PYTHONPATH=/tmp/site python3 -m hintsjax.run env=ant hint=speed scheme=fc out_dir=/tmp/r/ant
# Transfers of at most 64 MiB at a time, the working tree included, are why warp-lang (149 MB) travels in parts, mujoco's
# wheel alone and pyopengl not at all (mujoco imports its OpenGL parts only when asked to).
# A poll's files come back only when it returns: keep SECONDS under the device time left (the lease's
# budget_left_s, which a 1-GPU machine can count in full), or a cut call brings back nothing. And keep a
# call in flight: a machine idle for idle_release_s (30 s, `status`) goes back, and its detached runs with it.
set -euo pipefail
PY=3.12
PLATFORMS="manylinux_2_28_x86_64 manylinux_2_27_x86_64 manylinux_2_17_x86_64 manylinux2014_x86_64 manylinux1_x86_64 any"
WARP=warp_lang-1.18.0-py3-none-manylinux_2_28_x86_64.whl
WARP_MD5=47fc34ed07880e32d2964187ad4de4cd
WARP_PARTS=6  # 25 MB each: one travels beside the working tree (about 33 MiB) within a call's 64 MiB
# What the GPU image lacks among the project's pins (pyproject.toml) and their needs
CARRIED="mujoco==3.17.0 mujoco-mjx==3.17.0 hydra-core==1.3.2 omegaconf==2.3.0 tensorboardX==2.6.5 trimesh websockets>=13"
# What env=playground:* and experiments/playground.py need beyond those (importing mujoco_playground and brax
# worked with these on the GPU image, 2026-11-28; Playground's tasks with their vision off, as hintsjax steps
# them, need no warp-lang: its import blocked, on a CPU, 2026-12-07)
PLAYGROUND="playground==0.2.0 brax==0.14.2 jaxopt==0.8.5 ml_collections==1.1.0 mediapy==1.2.7 lxml==6.1.3 flask==3.1.3 flask-cors==6.0.5"

download() {  # download DEST SPEC...: binary wheels for PY on PLATFORMS, without their dependencies
    local dest=$1; shift
    local flags=(--no-deps --only-binary=:all: --python-version "$PY" --implementation cp -d "$dest")
    for p in $PLATFORMS; do flags+=(--platform "$p"); done
    python3 -m pip download -q "${flags[@]}" "$@"
}

case "${1:-}" in
wheels)
    mkdir -p .whl2 .whl3 .wp
    download .whl2 $CARRIED
    download .whl3 $PLAYGROUND
    python3 -m pip wheel -q --no-deps -w .whl2 antlr4-python3-runtime==4.9.3  # hydra's parser: an sdist only
    python3 -m pip wheel -q --no-deps -w .whl2 .                              # this project, as it stands here
    tmp=$(mktemp -d) && download "$tmp" warp-lang==1.18.0
    echo "$WARP_MD5  $tmp/$WARP" | md5sum -c -
    (cd .wp && rm -f warp.part.* && split -n "$WARP_PARTS" -d "$tmp/$WARP" warp.part.) && rm -r "$tmp"
    mkdir -p .whl && rm -f .whl/*.whl && mv .whl2/mujoco-[0-9]*.whl .whl/  # alone: 27 MB beside the tree
    du -sh .whl .whl2 .whl3 .wp ;;
calls)
    # What one device call carries: the working tree (git's tracked files and the untracked ones it
    # does not ignore) and its `carry` paths, at most 64 MiB together
    tree=$( { git ls-files -z; git ls-files -z -o --exclude-standard; } | xargs -0 du -cb 2>/dev/null | awk '$2 == "total" {n += $1} END {print n}')
    plan() {  # plan CARRY... -- COMMAND
        local carried=() size=$tree
        while [ "$1" != "--" ]; do carried+=("\"$1\""); size=$((size + $(du -cb "$1" | tail -1 | cut -f1))); shift; done
        shift
        local mark=ok; [ "$size" -le $((64 * 1024 * 1024)) ] || mark="OVER 64 MiB"
        printf '%s MiB %s  carry [%s]  %s\n' "$((size / 1024 / 1024))" "$mark" "$(IFS=,; echo "${carried[*]}")" "$*"
    }
    plan .whl -- "mkdir -p /tmp/wheels && cp .whl/*.whl /tmp/wheels/"
    plan .whl2 .whl3 -- "cp .whl2/*.whl .whl3/*.whl /tmp/wheels/ && bash experiments/offline_gpu.sh install /tmp/wheels"
    for part in .wp/warp.part.0[0-9]; do plan "$part" -- "bash experiments/offline_gpu.sh warp   # physics=warp only"; done
    echo "then, in the last of them or the next: (setsid nohup bash SCRIPT > /tmp/lease.out 2>&1 < /dev/null &), and keep a poll in flight" ;;
install)
    python3 -m pip install -q --no-index --no-deps --no-compile --no-cache-dir --upgrade --target /tmp/site "${2:-.whl2}"/*.whl
    cd /tmp && PYTHONPATH=/tmp/site python3 -c "import jax, mujoco, hintsjax.envs; print('jax', jax.__version__, 'mujoco', mujoco.__version__, jax.devices())" ;;
warp)
    mkdir -p /tmp/wparts && cp .wp/warp.part.* /tmp/wparts/ 2>/dev/null || true
    ls /tmp/wparts
    if [ "$(ls /tmp/wparts | wc -l)" -eq "$WARP_PARTS" ]; then
        cat /tmp/wparts/warp.part.0? > "/tmp/$WARP"
        echo "$WARP_MD5  /tmp/$WARP" | md5sum -c -
        python3 -m pip install -q --no-index --no-deps --no-compile --no-cache-dir --target /tmp/site "/tmp/$WARP"
        cd /tmp && PYTHONPATH=/tmp/site python3 -c "import warp; print('warp', warp.__version__)"
    fi ;;
poll)
    end=$((SECONDS + ${2:?seconds}))
    while [ $SECONDS -lt $end ] && [ ! -e "/tmp/${3:?marker}" ]; do sleep 5; done
    date; nvidia-smi --query-gpu=index,utilization.gpu,memory.used --format=csv,noheader || true
    for f in /tmp/logs/*.log; do
        [ -e "$f" ] || continue
        echo "== $f"; tail -c 1500 "$f" | tr '\r' '\n' | { grep -v '^\s*$' || true; } | tail -5  # an empty log too
    done
    if [ -d /tmp/r ]; then
        (cd /tmp && find r logs -type f -size -20M \( -name '*.csv' -o -name '*.json' -o -name '*.jsonl' -o -name '*.yaml' -o -name '*.log' \) \
            -print0 | tar czf "${OUT:-/tmp}/runs.tgz" --null -T -)
    fi ;;
*)
    sed -n '2,16p' "$0"; exit 2 ;;
esac
