"""An outside learner on hintsjax.gym (issue 63): Stable-Baselines3's PPO with MultiInputPolicy on
`hintsjax/pendulum-v0` (64x64 pictures and the composite hint), against a random policy, and the
wrapper's env steps/s against Gymnasium's own Pendulum-v1 drawn (render_mode="rgb_array") and
resized to 64x64, at the same number of envs on the same CPU. Needs the `gym` extra.

    python experiments/gym_sb3.py --part rate  --num-envs 16 --steps 2000
    python experiments/gym_sb3.py --part train --num-envs 8 --timesteps 32768 --image-size 36
        --seed 0
    python experiments/gym_sb3.py --part all ... --out experiments/results/gym.json

Results: experiments/results/gym.md (and the JSON it is read from).
"""

from __future__ import annotations

import argparse
import json
import platform
import subprocess
import sys
import time
from pathlib import Path

import gymnasium
import numpy as np

import hintsjax.gym  # noqa: F401  (registers hintsjax/<env>-v0)

ENV_ID = "hintsjax/pendulum-v0"
SETTINGS = dict(hint="composite", variant="swingup")


def hintsjax_rate(num_envs: int, steps: int, seed: int) -> dict:
    """Env steps/s of the vector env (pictures and hint) under uniform random actions, after a
    warm-up that compiles; an episode's end and its reset inside the timed steps."""
    env = gymnasium.make_vec(ENV_ID, num_envs=num_envs, **SETTINGS)
    env.action_space.seed(seed)
    t0 = time.perf_counter()
    env.reset(seed=seed)
    env.step(env.action_space.sample())
    compile_s = time.perf_counter() - t0
    acts = [env.action_space.sample() for _ in range(steps)]
    t0 = time.perf_counter()
    for a in acts:
        obs, *_ = env.step(a)
    seconds = time.perf_counter() - t0
    assert obs["pixels"].shape == (num_envs, 64, 64, 3)
    return dict(
        num_envs=num_envs,
        steps=steps,
        seconds=seconds,
        env_steps_per_s=num_envs * steps / seconds,
        first_reset_and_step_s=compile_s,
    )


def gymnasium_rate(num_envs: int, steps: int, seed: int) -> dict:
    """The same for Gymnasium's Pendulum-v1 as pixels the usual way: render_mode="rgb_array"
    (pygame, 500x500), AddRenderObservation (the picture as the observation) and ResizeObservation
    to 64x64 (OpenCV), in SyncVectorEnv (the envs stepped one after another in this process)."""
    from gymnasium.wrappers import AddRenderObservation, ResizeObservation

    def make():
        return ResizeObservation(
            AddRenderObservation(gymnasium.make("Pendulum-v1", render_mode="rgb_array")), (64, 64)
        )

    env = gymnasium.vector.SyncVectorEnv([make for _ in range(num_envs)])
    env.action_space.seed(seed)
    env.reset(seed=seed)
    env.step(env.action_space.sample())
    acts = [env.action_space.sample() for _ in range(steps)]
    t0 = time.perf_counter()
    for a in acts:
        obs, *_ = env.step(a)
    seconds = time.perf_counter() - t0
    assert obs.shape == (num_envs, 64, 64, 3) and obs.dtype == np.uint8
    return dict(
        num_envs=num_envs, steps=steps, seconds=seconds, env_steps_per_s=num_envs * steps / seconds
    )


def episode_returns(
    policy, num_envs: int, episodes: int, seed: int, image_size: int
) -> list[float]:
    """Undiscounted returns of `episodes` whole episodes (the pendulum's all last 200 steps, so the
    envs end together), `policy(obs) -> actions`."""
    env = gymnasium.make_vec(ENV_ID, num_envs=num_envs, image_size=image_size, **SETTINGS)
    returns: list[float] = []
    obs, _ = env.reset(seed=seed)
    total = np.zeros(num_envs)
    while len(returns) < episodes:
        obs, reward, terminated, truncated, _ = env.step(policy(obs))
        total += reward
        for i in np.flatnonzero(terminated | truncated):
            returns.append(float(total[i]))
            total[i] = 0.0
    return returns[:episodes]


def train(
    num_envs: int,
    timesteps: int,
    seed: int,
    eval_episodes: int,
    threads: int,
    image_size: int,
    n_steps: int,
    epochs: int,
    batch_size: int,
    normalize_reward: bool,
) -> dict:
    """SB3 PPO (MultiInputPolicy: NatureCNN on the picture, beside the hint) on the pendulum for
    `timesteps` env steps, pictures `image_size` a side, rewards scaled by SB3's VecNormalize where
    `normalize_reward`; the greedy policy's and a uniform random policy's returns (the env's own
    rewards) from the same evaluation seeds."""
    import torch
    from stable_baselines3 import PPO
    from stable_baselines3.common.vec_env import VecNormalize

    from hintsjax.gym.sb3 import VecEnv

    torch.set_num_threads(threads)
    venv = VecEnv(gymnasium.make_vec(ENV_ID, num_envs=num_envs, image_size=image_size, **SETTINGS))
    if normalize_reward:
        venv = VecNormalize(venv, norm_obs=False, norm_reward=True, gamma=0.9)
    # rl-zoo's Pendulum-v1 settings (gamma 0.9, gae 0.95, lr 1e-3, 10 epochs of minibatches of 64,
    # gSDE sampled every 4 steps, no entropy bonus); the defaults here roll out 8 x 256 steps an
    # update (rl-zoo: 4 x 1024)
    hyper = dict(
        n_steps=n_steps,
        batch_size=batch_size,
        n_epochs=epochs,
        gamma=0.9,
        gae_lambda=0.95,
        learning_rate=1e-3,
        clip_range=0.2,
        ent_coef=0.0,
        use_sde=True,
        sde_sample_freq=4,
    )
    model = PPO("MultiInputPolicy", venv, seed=seed, verbose=0, device="cpu", **hyper)
    t0 = time.perf_counter()
    model.learn(total_timesteps=timesteps)
    train_s = time.perf_counter() - t0
    eval_seed = 10_000 + seed
    trained = episode_returns(
        lambda obs: model.predict(obs, deterministic=True)[0],
        num_envs,
        eval_episodes,
        eval_seed,
        image_size,
    )
    rng = np.random.default_rng(eval_seed)
    random = episode_returns(
        lambda obs: rng.uniform(-2.0, 2.0, (num_envs, 1)).astype(np.float32),
        num_envs,
        eval_episodes,
        eval_seed,
        image_size,
    )
    return dict(
        num_envs=num_envs,
        image_size=image_size,
        timesteps=int(model.num_timesteps),
        seed=seed,
        hyper=hyper,
        normalize_reward=normalize_reward,
        train_seconds=train_s,
        env_steps_per_s=model.num_timesteps / train_s,
        torch_threads=threads,
        eval_seed=eval_seed,
        eval_episodes=eval_episodes,
        trained_mean=float(np.mean(trained)),
        trained_std=float(np.std(trained)),
        random_mean=float(np.mean(random)),
        random_std=float(np.std(random)),
        trained=trained,
        random=random,
    )


def machine() -> dict:
    import jax
    import torch

    model = next(
        (
            line.split(":", 1)[1].strip()
            for line in subprocess.run(
                ["lscpu"], capture_output=True, text=True
            ).stdout.splitlines()
            if line.startswith("Model name")
        ),
        platform.processor(),
    )
    return dict(
        cpu=model,
        cores=len(__import__("os").sched_getaffinity(0)),
        python=platform.python_version(),
        jax=jax.__version__,
        torch=torch.__version__,
        gymnasium=gymnasium.__version__,
        stable_baselines3=__import__("stable_baselines3").__version__,
        jax_backend=jax.default_backend(),
    )


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--part", choices=("rate", "train", "all"), default="all")
    parser.add_argument("--num-envs", type=int, default=16)
    parser.add_argument(
        "--steps", type=int, default=2000, help="timed vector steps per rate measurement"
    )
    parser.add_argument(
        "--timesteps", type=int, default=40_960, help="SB3's training budget in env steps"
    )
    parser.add_argument("--eval-episodes", type=int, default=32)
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--threads", type=int, default=2, help="torch's CPU threads")
    parser.add_argument(
        "--image-size",
        type=int,
        default=64,
        help="training's pictures, pixels a side (the rate's are 64)",
    )
    parser.add_argument("--n-steps", type=int, default=256, help="SB3's rollout length per env")
    parser.add_argument("--epochs", type=int, default=10)
    parser.add_argument("--batch-size", type=int, default=64, help="SB3's minibatch")
    parser.add_argument("--normalize-reward", action=argparse.BooleanOptionalAction, default=True)
    parser.add_argument("--out", type=Path, help="write the results as JSON here")
    args = parser.parse_args()
    result: dict = dict(
        command=" ".join(["python experiments/gym_sb3.py", *sys.argv[1:]]),
        settings=vars(args) | dict(out=str(args.out)),
        machine=machine(),
    )
    if args.part in ("rate", "all"):
        result["rate"] = dict(
            hintsjax=hintsjax_rate(args.num_envs, args.steps, args.seed),
            gymnasium=gymnasium_rate(args.num_envs, args.steps, args.seed),
        )
        print(json.dumps(result["rate"], indent=1))
    if args.part in ("train", "all"):
        result["train"] = train(
            args.num_envs,
            args.timesteps,
            args.seed,
            args.eval_episodes,
            args.threads,
            args.image_size,
            args.n_steps,
            args.epochs,
            args.batch_size,
            args.normalize_reward,
        )
        print(
            json.dumps(
                {k: v for k, v in result["train"].items() if k not in ("trained", "random")},
                indent=1,
            )
        )
    if args.out:
        args.out.write_text(json.dumps(result, indent=1) + "\n")


if __name__ == "__main__":
    main()
