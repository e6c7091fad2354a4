#!/usr/bin/env bash
# The GPU runs the open issues still wait for (82: the ant's update and command; 83: Playground's
# side by side), each issue's in the order they matter, as one detached job a lease of one GPU.
# Set up with experiments/offline_gpu.sh's calls (`calls` lists them): for 83's part the first
# two, the second ending in `&& bash experiments/gpu_queue.sh start 83`; for 82's all eight, the
# last ending in `&& bash experiments/gpu_queue.sh start 82`. Then:
#
#   bash experiments/offline_gpu.sh poll 240 queue_done   # again and again: keep a call in flight
#
# start copies the repo to /tmp/repo and runs detached. Each run writes into /tmp/r (which poll
# packs into $OUT/runs.tgz) and logs into /tmp/logs. A lease holds a machine for 30 minutes, the
# setup takes 1 to 3, and whatever the queue reached comes back (estimates from one H200: each knob
# side about 5 minutes if Brax's CNN trains at hintsjax's CNN's rate, so 83's part 35 after its
# 2-minute profile, two leases; the bench pair 4, the profile 1.5, the typed command 8.5,
# so 82's 14). Once a run is back, take it off here.
#
# `start 83` (or `start 82`) runs one issue's part (`start` both, 83's first): 83's needs no
# warp-lang (Playground's task with its vision off, stepped by MJX's JAX physics), so only the
# first two setup calls, not eight.
set -u
case "${1:-}" in
start)
    shift
    for issue in "$@"; do
        case $issue in 83|82) ;; *) echo "no runs for issue $issue: 83, 82" >&2; exit 2 ;; esac
    done
    # the queue imports the installed project: refuse one built from another tree (its wheel is
    # built here by `offline_gpu.sh wheels`, from the tree as it stood then)
    [ -d hintsjax ] && [ -d envs ] || { echo "start runs from the repo's root" >&2; exit 2; }
    stale=$(for pair in hintsjax:hintsjax envs:hintsjax/envs; do  # here:installed
        find "${pair%%:*}" -name '*.py' | while read -r f; do
            cmp -s "$f" "/tmp/site/${pair#*:}/${f#*/}" || echo "$f"; done; done)
    if [ -n "$stale" ]; then
        echo "the installed hintsjax is not this tree's ($(echo $stale | cut -c1-200)): run" \
            "'bash experiments/offline_gpu.sh wheels' here and the setup calls again" >&2
        exit 2
    fi
    rm -rf /tmp/repo && cp -r . /tmp/repo
    (setsid nohup bash /tmp/repo/experiments/gpu_queue.sh run "$@" > /tmp/queue.out 2>&1 < /dev/null &)
    echo "queue started: /tmp/queue.out, /tmp/logs" ;;
run)
    export PYTHONPATH=/tmp/site PYTHONUNBUFFERED=1
    R=/tmp/repo L=/tmp/logs
    mkdir -p $L /tmp/r/runs/playground /tmp/r/bench /tmp/r/typed
    shift
    issues=("$@")
    [ ${#issues[@]} -gt 0 ] || issues=(83 82)
    for issue in "${issues[@]}"; do case $issue in
    83)
    # 83: the seven knob sides between the mapped side and Playground's (5 seeds each), every
    # knob at once first, then the networks' three together, then the rest between them (a lease
    # cut short still says how much of the gap the knobs close; the next lease goes on with the
    # sides its record lacks); back here, the record replaces the archived one and
    # `playground_vision.py --report --runs experiments/results/runs/playground` writes the section
    # First where the mapped side spends its update (a seed's share of its rate was 0.88x
    # Playground's seed: the record's section), a minute; then the split of the learner with
    # Brax's CNN, one a network, with and without XLA's deterministic ops (a lease ran
    # mapped_scale at 3,413 env steps/s a seed against mapped's 22,395; the max-pool's gradient,
    # select-and-scatter, was the suspect: max_pool_2x2 since).
    (cd /tmp/r && python3 $R/experiments/playground_vision.py --side mapped --seeds 5 \
        --parts /tmp/r/parts_mapped.json) > $L/parts_mapped.log 2>&1
    (cd /tmp/r && python3 $R/experiments/profile_update.py --part learn \
        --env playground:CartpoleBalance:vision --ppo encoder=brax_vision,critic_encoder=own \
        --variants base,nodet --updates 5 --seeds 5 --top 25 --out /tmp/r/profile_brax_cnn) \
        > $L/profile_brax_cnn.log 2>&1
    # (the archived record once: a second start on this machine goes on from its own)
    [ -e /tmp/r/runs/playground/versus_vision.json ] ||
        cp $R/experiments/results/runs/playground/versus_vision.json /tmp/r/runs/playground/
    for side in mapped_timeout mapped_scale mapped_std mapped_loss mapped_swish mapped_cnn \
        mapped_nets; do
        python3 -c 'import json, sys; sys.exit(sys.argv[1] not in json.load(open(sys.argv[2]))["results"])' \
            $side /tmp/r/runs/playground/versus_vision.json && continue  # in the record already
        (cd /tmp/r && python3 $R/experiments/playground_vision.py --side $side --seeds 5 \
            --runs runs/playground) > $L/$side.log 2>&1
    done ;;
    82)
    # 82: an update's parts under Warp, the rollout's starts drawn for every env or the ended ones
    # (hintsjax.algorithms.ppo.ENDED_STARTS_PHYSICS holds JAX alone until this says otherwise)
    for s in every_env ended; do
        (cd /tmp/r/bench && python3 $R/experiments/bench.py --parts --envs ant --physics warp \
            --rollout-starts $s --warm-rollouts 249 --out /tmp/r/bench/$s.json) > $L/bench_$s.log 2>&1
    done
    # 82: the ant's learner without deterministic ops (as its Warp run trains), by XLA op
    (cd /tmp/r && python3 $R/experiments/profile_update.py --part learn --env ant --physics jax \
        --variants nodet --updates 10 --seeds 5 --top 40 --out /tmp/r/profile) > $L/profile.log 2>&1
    # 82: the design's command as a new user types it, caches empty (run_path.json's row)
    rm -rf ~/.cache/hintsjax ~/.cache/warp
    (cd /tmp/r/typed && /usr/bin/time -v python3 -m hintsjax.run env=ant hint=speed scheme=fc) \
        > $L/typed.log 2>&1 ;;
    esac; done
    touch /tmp/queue_done ;;
*)
    sed -n '2,18p' "$0"; exit 2 ;;
esac
