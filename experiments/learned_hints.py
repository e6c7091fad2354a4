"""Hints without ground truth at deploy (issue 24): agents whose hints come from a learned generator.

    python experiments/learned_hints.py --cases pendulum:composite,acrobot:composite --seeds 10
    python experiments/learned_hints.py --cases halfcheetah:velocity --seeds 5
                                        --parts generator,programmatic
    python experiments/learned_hints.py --frames-sweep 1,2,3,4 --cases pendulum:composite
    python experiments/learned_hints.py --report          # -> experiments/results/learned_hints.md

For each env:hint case, under --runs: a generator (hintsjax.generator, --gen-seeds seeds, data
from random actions in half the envs and the packaged expert in the other half), then HINTS-FC
trained with programmatic hints and evaluated with them and with the generator's (no
retraining), then HINTS-FC trained and evaluated with the generator's hints. Every agent run has
--seeds seeds x 50 episodes and the env's default budget. Finished steps are skipped and a run
cut off mid-way resumes from its checkpoint, so the command can be repeated until it is done.
`--frames-sweep` trains only generators, one per number of pictures, for the choice of that
default. `--report` reads the folders (and PPO-RGB's archived 20-seed rows; an env without one,
e.g. halfcheetah, gets a PPO-RGB run of --seeds seeds beside its case) and writes the table.
"""  # noqa: E501

from __future__ import annotations

import argparse
import json
from pathlib import Path

import numpy as np
from hintsjax.reproduce.archive import ARCHIVE, about_lines, read_about
from hintsjax.reproduce.markdown import markdown_table

RESULTS = Path(__file__).resolve().parent / "results"
CASES = (
    "pendulum:composite,pendulum:angular_velocity,acrobot:composite,idp:composite,"
    "halfcheetah:velocity"
)
GENERATOR = dict(
    policy="expert", expert_fraction=0.5, num_envs=64, steps=500, held_out_envs=16, epochs=10
)
# about.json: run folders that shared the GPU with other training (timings not costs)
SHARED_KEY = "shared_gpu_runs"
SHARED_CELL = "(shared GPU)"
PPO_RGB = RESULTS / "runs" / "classic20"  # PPO-RGB's archived rows: <env>/ppo_rgb/eval.json


def rgb_folder(runs: Path, env: str) -> Path:
    """PPO-RGB's run for `env`: the archived 20-seed row where there is one (classic control),
    else the one this script trains beside the case (e.g. halfcheetah's, whose table row predates
    the archive)."""
    archived = PPO_RGB / env / "ppo_rgb"
    return archived if (archived / "eval.json").is_file() else runs / f"{env}-ppo_rgb"


def generator_folder(runs: Path, env: str, hint: str, frames: int) -> Path:
    return runs / f"generator-{env}-{hint}-k{frames}"


def train_generator(runs: Path, env: str, hint: str, frames: int, seeds: int) -> Path:
    from hintsjax.hints import generators
    from hintsjax import generator

    folder = generator_folder(runs, env, hint, frames)
    if not (folder / generators.GENERATOR_JSON).is_file():
        if folder.exists():  # an interrupted one: train it again
            import shutil

            shutil.rmtree(folder)
        argv = [
            f"{k}={v}"
            for k, v in {
                **GENERATOR,
                "env": env,
                "hint": hint,
                "frames": frames,
                "seeds": seeds,
                "out_dir": runs,
                "name": folder.name,
            }.items()
        ]
        if generator.main(argv):
            raise SystemExit(f"generator {folder.name} failed")
    return folder


def train_agent(runs: Path, name: str, values: dict) -> Path:
    from hintsjax import run

    folder = runs / name
    if (folder / "eval.json").is_file():
        return folder
    common = {"out_dir": str(runs), "name": name, "checkpoint_seconds": 60}
    status = run.main_from_values(
        {"resume": str(folder)} if (folder / "config.yaml").is_file() else {**values, **common}
    )
    if status:
        raise SystemExit(f"run {name} failed ({status})")
    return folder


def deploy_with(folder: Path, source: Path) -> Path:
    from hintsjax import evaluate

    out = folder / f"eval-deploy-learned-{source.name}.json"
    if not out.is_file():
        if evaluate.main([str(folder), "--hint-source", str(source)]):
            raise SystemExit(f"evaluating {folder.name} with {source.name} failed")
        written = sorted(folder.glob(f"eval-*-hints-{source.name}.json"))[-1]
        written.rename(out)
    return out


# A case's pieces, in order; `--parts` runs some of them (e.g. where one device call cannot hold
# them all: a 5-seed halfcheetah run trained in 106 to 119 s alone on an H200; Table 3's cheetah
# runs, 7 sharing one H100, took about 1150 s each).
# Each piece needs the generator's folder, which the first makes.
PARTS = ("generator", "programmatic", "ppo_rgb", "learned")


def run_case(
    runs: Path,
    env: str,
    hint: str,
    frames: int,
    seeds: int,
    gen_seeds: int,
    parts: tuple[str, ...] = PARTS,
) -> None:
    source = train_generator(runs, env, hint, frames, gen_seeds)  # every other piece reads it
    base = {"env": env, "agent": "hints", "scheme": "fc", "hint": hint, "seeds": seeds}
    if "programmatic" in parts:
        deploy_with(train_agent(runs, f"{env}-{hint}-programmatic", base), source)
    # none archived: trained beside the case
    if "ppo_rgb" in parts and rgb_folder(runs, env).parent == runs:
        train_agent(
            runs, rgb_folder(runs, env).name, {"env": env, "agent": "ppo_rgb", "seeds": seeds}
        )
    if "learned" in parts:  # last: the report shows a case once this row is done
        train_agent(runs, f"{env}-{hint}-learned-k{frames}", {**base, "hint_source": str(source)})


# -- the report ----------------------------------------------------------------------------------


def seed_means(path: Path) -> np.ndarray:
    data = json.loads(path.read_text())
    return np.asarray(
        data["evaluations"][0]["seed_means"] if "evaluations" in data else data["seed_means"]
    )


def report_runs(runs: Path, cases: list[tuple[str, str]], frames: int) -> Path:
    """The folder --report reads: --runs where a case finished there, else its committed copy
    (archive.ARCHIVE/<its name>), so the report on a fresh checkout rebuilds the file."""
    finished = any(
        (runs / f"{env}-{hint}-learned-k{frames}" / "eval.json").is_file() for env, hint in cases
    )
    return runs if finished else ARCHIVE / runs.name


def report(runs: Path, cases: list[tuple[str, str]], frames: int, out: Path) -> None:
    from hintsjax.reproduce import stats

    lines = [
        "# Hints without ground truth at deploy: agents that see a learned generator's hints",
        "",
        "Written by `python experiments/learned_hints.py --report` from the runs of "
        "`python experiments/learned_hints.py --cases ... --seeds ...` "
        "(commands and hardware below). "
        "Returns: the mean over each seed's 50 deterministic episodes, then mean ± std over seeds, "
        "IQM with its 95% bootstrap interval (hintsjax/reproduce/stats.py), and P(row > PPO-RGB), "
        "the probability that a seed of the row beats a seed of PPO-RGB, with its 95% interval "
        "(decided where it excludes 0.5).",
        "",
    ]
    about = read_about(runs)
    # folders whose seconds are not a cost: the GPU ran other training too
    shared = set(about.pop(SHARED_KEY, []))
    rows, verdicts, against, costs = [], [], [], []
    for env, hint in cases:
        gen = generator_folder(runs, env, hint, frames)
        programmatic, learned = (
            runs / f"{env}-{hint}-programmatic",
            runs / f"{env}-{hint}-learned-k{frames}",
        )
        if not (learned / "eval.json").is_file():
            continue
        meta = json.loads((gen / "generator.json").read_text())
        r2 = ", ".join(
            f"{d} {m:.3f} (min {lo:.3f})"
            for d, m, lo in zip(meta["dimensions"], meta["heldout_r2_mean"], meta["heldout_r2_min"])
        )
        rgb_run = rgb_folder(runs, env)
        rgb = seed_means(rgb_run / "eval.json")
        entries = [
            ("trained and deployed with programmatic hints", programmatic / "eval.json"),
            (
                "trained with programmatic, deployed with learned hints",
                programmatic / f"eval-deploy-learned-{gen.name}.json",
            ),
            ("trained and deployed with learned hints", learned / "eval.json"),
        ]
        reference = seed_means(entries[0][1])
        for what, path in entries:
            x = seed_means(path)
            poi = stats.poi_ci(x, rgb)
            if path != entries[0][1]:
                against.append(
                    f"- {env} {hint}, {what}: "
                    + stats.ordering_text("learned", "programmatic", stats.poi_ci(x, reference))
                )
            rows.append(
                [
                    env,
                    hint,
                    what,
                    f"{x.mean():.1f} ± {x.std():.1f}",
                    stats.iqm_cell(x),
                    str(len(x)),
                    f"{poi.point:.2f} [{poi.low:.2f}, {poi.high:.2f}]",
                ]
            )
            verdicts.append(
                f"- {env} {hint}, {what}: " + stats.ordering_text("row", "PPO-RGB", poi)
            )
        rgb_what = (
            "PPO-RGB (archived 20-seed row)" if rgb_run.parent != runs else "PPO-RGB (trained here)"
        )
        rows.append(
            [
                env,
                "-",
                rgb_what,
                f"{rgb.mean():.1f} ± {rgb.std():.1f}",
                stats.iqm_cell(rgb),
                str(len(rgb)),
                "-",
            ]
        )
        rates = [
            None
            if f.name in shared
            else json.loads((f / "eval.json").read_text())["train_env_steps_per_s"]
            for f in (programmatic, learned)
        ]
        gen_cost = (
            SHARED_CELL
            if gen.name in shared
            else f"{meta['seconds']['compile']:.0f} + {meta['seconds']['train']:.0f}"
        )
        costs.append(
            [
                env,
                hint,
                r2,
                f"{meta['env_steps']:,}",
                gen_cost,
                *(SHARED_CELL if r is None else f"{r:,.0f}" for r in rates),
                "-" if None in rates else f"{1 - rates[1] / rates[0]:.0%}",
            ]
        )
    lines += [
        "## Returns",
        "",
        *markdown_table(
            [
                "env",
                "hint",
                "agent",
                "mean ± std over seeds",
                "IQM [95% CI]",
                "seeds",
                "P(> PPO-RGB) [95% CI]",
            ],
            rows,
        ),
        "",
    ]
    lines += ["## Against PPO-RGB", "", *verdicts, ""]
    lines += [
        "## Learned against programmatic hints",
        "",
        "The same comparison between each learned-hint row and the row trained and deployed with "
        "programmatic hints (for the deploy row: the very same agents, seed for seed).",
        "",
        *against,
        "",
    ]
    lines += [
        "## The generators and what they cost",
        "",
        f"Each generator: {frames} pictures, trained on rollouts of 64 envs x 500 steps "
        "(half driven by the packaged expert, half by N(0, 1) actions), held out: 16 more envs "
        "x 500 steps. R^2 is the held-out mean over the generator's seeds (and its worst seed); "
        "agents use seed 0. Training rate: the agent run's env steps per second (compiles "
        "excluded), programmatic against learned hints; the last column is the slowdown the "
        "generator's inference causes.",
        "",
        *markdown_table(
            [
                "env",
                "hint",
                "held-out R^2 per dimension",
                "data env steps",
                "generator compile + train (s)",
                "agent steps/s, programmatic",
                "agent steps/s, learned",
                "slowdown",
            ],
            costs,
        ),
        "",
    ]
    if (runs / "frames_sweep.json").is_file():
        sweep = json.loads((runs / "frames_sweep.json").read_text())
        lines += [
            "## How many pictures",
            "",
            "Held-out R^2 per hint dimension, mean over 3 generator seeds (worst seed), by the "
            "number of pictures the generator reads (`--frames-sweep 1,2,3,4 --gen-seeds 3`); "
            "everything else as above.",
            "",
            *markdown_table(
                ["env", "hint", "pictures", "held-out R^2", "compile + train (s)"],
                [
                    [
                        r["env"],
                        r["hint"],
                        str(r["frames"]),
                        ", ".join(
                            f"{d} {m:.3f} ({lo:.3f})"
                            for d, m, lo in zip(
                                r["dimensions"], r["heldout_r2_mean"], r["heldout_r2_min"]
                            )
                        ),
                        f"{r['seconds']['compile']:.0f} + {r['seconds']['train']:.0f}",
                    ]
                    for r in sweep
                ],
            ),
            "",
        ]
    if shared:
        about["shared GPU"] = (
            f"{', '.join(sorted(shared))} trained beside other training programs on the same GPU, "
            f"so their seconds are not a cost ({SHARED_CELL} above)"
        )
    lines += about_lines(about)
    out.write_text("\n".join(lines))
    print(f"wrote {out}")


def frames_sweep(runs: Path, cases: list[tuple[str, str]], choices: list[int], seeds: int) -> None:
    results = []
    for env, hint in cases:
        for k in choices:
            meta = json.loads(
                (train_generator(runs, env, hint, k, seeds) / "generator.json").read_text()
            )
            results.append(
                {
                    "env": env,
                    "hint": hint,
                    "frames": k,
                    "dimensions": meta["dimensions"],
                    "heldout_r2_mean": meta["heldout_r2_mean"],
                    "heldout_r2_min": meta["heldout_r2_min"],
                    "seconds": meta["seconds"],
                    "device": meta["device"],
                }
            )
            print(json.dumps(results[-1]), flush=True)
    (runs / "frames_sweep.json").write_text(json.dumps(results, indent=1))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--cases", default=CASES, help=f"env:hint pairs (default {CASES})")
    parser.add_argument("--seeds", type=int, default=10, help="seeds per agent run")
    parser.add_argument("--gen-seeds", type=int, default=5, help="seeds per generator")
    parser.add_argument("--frames", type=int, default=2, help="pictures the generator reads")
    parser.add_argument(
        "--frames-sweep",
        default=None,
        help="comma-separated numbers of pictures: train generators only",
    )
    parser.add_argument("--runs", type=Path, default=Path("runs/learned_hints"))
    parser.add_argument(
        "--parts",
        default=",".join(PARTS),
        help=f"comma-separated pieces of each case to run (default: all, {', '.join(PARTS)}; the "
        "generator is trained first whenever it is missing)",
    )
    parser.add_argument("--report", action="store_true")
    parser.add_argument("--out", type=Path, default=RESULTS / "learned_hints.md")
    args = parser.parse_args()
    cases = [tuple(c.split(":")) for c in args.cases.split(",")]
    parts = tuple(x for x in args.parts.split(",") if x)
    if not parts or any(x not in PARTS for x in parts):
        parser.exit(
            2, f"error: unknown --parts {args.parts!r}; valid choices: {', '.join(PARTS)}\n"
        )
    if args.report:
        report(report_runs(args.runs, cases, args.frames), cases, args.frames, args.out)
        return
    args.runs.mkdir(parents=True, exist_ok=True)
    if args.frames_sweep:
        frames_sweep(
            args.runs, cases, [int(k) for k in args.frames_sweep.split(",")], args.gen_seeds
        )
    else:
        for env, hint in cases:
            run_case(args.runs, env, hint, args.frames, args.seeds, args.gen_seeds, parts)


if __name__ == "__main__":
    main()
