"""experiments/playground_vision.py, hintsjax's pixel PPO beside Playground's vision PPO (issue
83): the env steps both sides take (Brax's own count), Playground's settings as hintsjax's, the
section's cells from a hand-written record, and (slow) Playground's side end to end on a CPU with
its renderer blank."""

from __future__ import annotations

import json
import math

import pytest

pytest.importorskip("mujoco_playground", reason="the side by side needs the playground extra")

import playground_stub  # noqa: E402
import playground_vision as pv  # noqa: E402

from hintsjax.settings.layers import run_config  # noqa: E402


def test_both_sides_take_brax_s_own_env_steps_with_playground_s_settings_mapped():
    """Playground's 5 M env steps are 4 epochs of ceil(5 M / (4 x 40,960)) = 31 Brax training steps
    of 256 x 8 x 20: 124 updates, 5,079,040 env steps, which both hintsjax sides take exactly."""
    s = pv.vision_settings(smoke=False)
    assert json.loads(json.dumps(s))["network_factory"]["cnn_kernel_init_kwargs"] == {
        "scale": 1.41421356
    }  # the record holds them
    assert (s["num_timesteps"], s["num_evals"], s["num_resets_per_eval"]) == (5_000_000, 5, 0)
    assert pv.steps_per_update(s) == 40_960 and pv.brax_updates(s) == 4 * 31 == 124
    mapped_cfg = run_config(pv.mapped_values(s, seeds=5, smoke=False))
    mapped = mapped_cfg.ppo
    # Playground's agent sees its last 3 frames; mapped_one sees one, as the paper's agents do
    assert mapped_cfg.frames == 3 == pv.PLAYGROUND_FRAMES
    assert run_config(pv.mapped_values(s, seeds=5, smoke=False, frames=1)).frames == 1
    # grey, as Playground's; mapped_first (archived) saw one RGB picture
    assert mapped_cfg.colour == "grey"
    assert run_config(pv.mapped_values(s, 5, False, 1, False, "rgb")).colour == "rgb"
    # and the entropy bonus of Brax's tanh-normal, the squashed action's
    assert mapped.squashed_entropy
    assert not run_config(pv.mapped_values(s, 5, False, 1, squashed=False)).ppo.squashed_entropy
    assert (mapped.num_envs, mapped.rollout_length, mapped.minibatch_size, mapped.epochs) == (
        1024,
        40,
        5120,
        8,
    )
    assert mapped.num_updates * mapped.batch_size == 5_079_040
    assert (mapped.gae_segment, mapped.clip_eps, mapped.ent_coef, mapped.max_grad_norm) == (
        20,
        0.3,
        0.02,
        1.0,
    )
    assert mapped.action_head == "tanh" and mapped.hidden == (128, 64)
    assert mapped.encoder_lr == mapped.actor_lr == mapped.critic_lr == 1e-3
    # Brax's CNN shared by actor and critic (mapped_cnn), then one a network as Brax's (mapped_nets)
    assert (mapped.encoder, mapped.critic_encoder) == ("nature", "shared")
    nets = run_config(pv.mapped_values(s, 5, False, encoder="brax_vision", critic_encoder="own"))
    assert (nets.ppo.encoder, nets.ppo.critic_encoder) == ("brax_vision", "own")
    assert mapped.pixel_scale == nets.ppo.pixel_scale == 1.0
    # and Playground's pixel range (mapped_scale)
    assert run_config(pv.mapped_values(s, 5, False, pixel_scale=0.5)).ppo.pixel_scale == 0.5
    # and Brax's value loss, 0.5 x its vf_loss_coefficient 0.5 x the mean square (mapped_loss)
    assert mapped.vf_coef == 0.5 and pv.BRAX_VALUE_WEIGHT == 0.25
    # each knob side's settings are the side before it's and its own knob; the last, every one
    last = run_config(pv.mapped_values(s, 5, False, **pv.MAPPED_KNOBS["mapped_timeout"])).ppo
    assert (last.encoder, last.critic_encoder, last.pixel_scale, last.vf_coef) == (
        "brax_vision",
        "own",
        0.5,
        0.25,
    )
    assert (last.activation, last.std_head, last.bootstrap_truncated) == (
        "swish",
        "softplus",
        False,
    )
    assert (mapped.activation, mapped.std_head, mapped.bootstrap_truncated) == (
        "relu",
        "param",
        True,
    )
    chain = [side for side, _ in pv.KNOB_STEPS if side in pv.MAPPED_KNOBS][3:]  # from mapped on
    for before, after in zip(chain, chain[1:]):
        assert pv.MAPPED_KNOBS[before].items() < pv.MAPPED_KNOBS[after].items(), (before, after)
    assert set(pv.MAPPED_KNOBS) == {side for side in pv.SIDES if side.startswith("mapped")}
    defaults = run_config(pv.default_values(s, seeds=5, smoke=False))
    assert (
        defaults.env == pv.ENV and defaults.ppo.num_updates * defaults.ppo.batch_size == 5_079_040
    )
    assert defaults.ppo.num_envs == 128  # the env's own (envs/playground.py PIXEL_PPO)


def test_the_section_gives_each_side_its_cells_and_hintsjax_against_playground(tmp_path):
    """Steady training rates leave the compiling epochs (Brax's first two) or chunk (hintsjax's
    first) out: Brax's `training/sps` of its later epochs, averaged; hintsjax's steps over seconds
    between its first and last chunk. Playground's seconds given apart: before its first epoch,
    and its compiling epochs' seconds beyond the steady rate; its evaluations between epochs are
    what its seconds hold beyond those before the first epoch and its training's."""
    memory = {"xla_peak_mib": 900, "nvidia_smi_peak_mib": 2100}
    side = {"eval_episodes": 128, "device": "NVIDIA H200", "date": "2026-12-03 10:00",
            "command": "python x", "memory": memory}  # fmt: skip
    run = {
        "seconds": 100.0,
        "renderer_build_seconds": 2.0,
        # 75 steps an epoch at a steady 25/s: 3 s; the first two compile (8 s, 3 s more)
        "progress": [
            {"step": 0, "seconds": 30.0, "eval/episode_reward": 1.0},
            {"step": 75, "seconds": 50.0, "training/sps": 6.8, "training/walltime": 11.0},
            {"step": 150, "seconds": 65.0, "training/sps": 12.5, "training/walltime": 17.0},
            {"step": 225, "seconds": 80.0, "training/sps": 25.0, "training/walltime": 20.0},
            {"step": 300, "seconds": 95.0, "training/sps": 25.0, "training/walltime": 23.0},
        ],
    }
    record = {
        "task": "CartpoleBalance",
        "seeds": 3,
        "env_steps_per_seed": 300,
        "smoke": False,
        "results": {
            "playground": {
                **side,
                "trainer": pv.TRAINERS["playground"],
                "seconds": 300.0,
                "renderer_build_seconds": 6.0,
                "seeds_run": [run] * 3,
                "deterministic": [10.0, 11.0, 12.0],
                "env_steps_per_seed": 300,
                "patches": ["one patch"],
            },  # fmt: skip
            "mapped": {
                **side,
                "trainer": pv.TRAINERS["mapped"],
                "seconds": 50.0,
                "compile_seconds": 20.0,
                "deterministic": [20.0, 21.0, 22.0],
                "env_steps_per_seed": 300,
                "progress": [{"step": 100, "seconds": 30.0}, {"step": 300, "seconds": 40.0}],
                "settings": {"frames": 3, "colour": "grey"},
            },
        },  # fmt: skip
    }
    (tmp_path / pv.RECORD).write_text(json.dumps(record))
    text = "\n".join(pv.section_lines(tmp_path))
    assert "3 seeds x 300 env steps a seed on every side" in text
    assert "| Playground + brax.training vision PPO | 3 grey | 300 | 11.0 [" in text
    # a seed: 30 s before its first epoch, 8 + 3 compiling; 3 seeds
    assert "| 10.0 11.0 12.0 | 300 | 123 (renderer 6) | 25 | 2100 / 900 |" in text
    # a seed's 100 s less 30 before training and 23 of training: 47 s of evaluations
    assert "Playground's wall-clock holds at most 141 s of Brax's evaluations between" in text
    assert "| 20.0 21.0 22.0 | 50 | 20 | 20 | 2100 / 900 |" in text  # 200 steps in 10 s
    assert f"| {pv.TRAINERS['mapped']} | 3 grey | 300 |" in text
    # 3 seeds in 50 s against 300 s; 3 x 20 env steps/s at once against Playground's 25
    assert "its 3 seeds in 50 s against 300 s (6.0x faster), training 60 env steps/s" in text
    assert "at once against 25 (2.4x)" in text
    assert (
        "| hintsjax ppo_rgb, its defaults | - |" in text
        and "| hintsjax ppo_rgb, Playground's settings, one picture | - |" in text
        and "Patches to Playground's side: one patch" in text
    )
    assert (
        f"P({pv.TRAINERS['mapped']} > {pv.TRAINERS['playground']}) = 1.00 [1.00, 1.00]: decided"
        in text
    )
    assert "processes" not in text  # Playground's seeds in one process
    # under the knob steps, what no side maps, one item a line
    assert "\nWhat no side maps yet:\n- the inits: Brax's MLPs LeCun-uniform" in text
    assert all(f"\n- {item}\n" in text for item in pv.UNMAPPED)
    runs = [{**run, "process": p} for p in ("2026-12-03 10:00:00", "2026-12-04 09:00:00") * 2][:3]
    record["results"]["playground"]["seeds_run"] = runs
    (tmp_path / pv.RECORD).write_text(json.dumps(record))
    text = "\n".join(pv.section_lines(tmp_path))
    assert "Playground's seeds were trained in 2 processes, one a GPU lease" in text
    # Playground's seeds finished, its entry not yet written: their rows say what they got
    del record["results"]["playground"]
    (tmp_path / pv.RECORD).write_text(json.dumps(record))
    budget = {k: record[k] for k in ("task", "seeds", "env_steps_per_seed", "smoke")}
    rows = [
        {"seed": i, "budget": budget, "seconds": 100.0 + i, "deterministic": 24.0 + i / 10,
         "device": "NVIDIA H200", "date": "2026-12-04 03:55"}
        for i in range(2)
    ] + [{"seed": 2, "budget": {**budget, "seeds": 9}, "seconds": 1.0, "deterministic": 0.0,
          "device": "NVIDIA H100", "date": "2026-12-01 00:00"}]  # fmt: skip
    (tmp_path / pv.SEEDS_DONE).write_text("\n".join(map(json.dumps, rows)))
    text = "\n".join(pv.section_lines(tmp_path))
    assert (
        "Playground's side has 2 of 3 seeds finished, its entry not written yet" in text
        and "final returns 24.0 24.1, 201 s in all (NVIDIA H200, 2026-12-04)." in text
    )


@pytest.mark.slow
def test_playground_s_side_trains_and_evaluates_with_its_renderer_blank(monkeypatch, tmp_path):
    """Brax's vision PPO on Playground's CartpoleBalance, as the script calls it, on a CPU (its
    renderer blank, its physics MuJoCo Warp's on the CPU): one seed at the smoke budget, Brax's
    evaluations timed, the final policy on 4 fresh episodes; the seed's row kept, so that a second
    process takes it instead of training it again, and a row of another budget is not taken."""
    from brax.training.agents.ppo import train as ppo

    playground_stub.blank_renderer(monkeypatch)
    s = pv.vision_settings(smoke=True)
    done, budget = tmp_path / pv.SEEDS_DONE, {"task": pv.TASK, "env_steps_per_seed": 2048}
    out = pv.train_playground(s, seeds=1, episodes=4, done_path=done, budget=budget)
    steps = pv.brax_updates(s) * pv.steps_per_update(s)
    assert out["env_steps_per_seed"] == steps == 2048
    progress = out["seeds_run"][0]["progress"]
    assert [row["step"] for row in progress] == [0, 2048] and "training/sps" in progress[-1]
    assert len(out["deterministic"]) == 1 and math.isfinite(out["deterministic"][0])
    assert out["seconds"] >= progress[-1]["seconds"] > progress[0]["seconds"] > 0
    assert [row["seed"] for row in map(json.loads, done.read_text().splitlines())] == [0]

    def trains(**kwargs):
        raise AssertionError("a finished seed trained again")

    monkeypatch.setattr(ppo, "train", trains)
    again = pv.train_playground(s, seeds=1, episodes=4, done_path=done, budget=budget)
    assert again["deterministic"] == out["deterministic"]
    assert again["seeds_run"] == out["seeds_run"]
    with pytest.raises(AssertionError, match="trained again"):
        pv.train_playground(s, 1, 4, done_path=done, budget={**budget, "env_steps_per_seed": 1})


def test_a_playground_seed_of_one_epoch_counts_it_as_compiling():
    """A smoke budget's one epoch: its seconds beyond a steady rate are unknown (no later epoch),
    not an error; the time before it and the evaluations still add up."""
    first = {"step": 75, "seconds": 40.0, "training/sps": 3.0, "training/walltime": 25.0}
    run = {"seconds": 50.0, "progress": [{"step": 0, "seconds": 10.0}, first]}
    out = pv.playground_overheads({"seeds_run": [run, run]})
    assert out["before"] == 20.0 and out["evaluations"] == 30.0 and math.isnan(out["compiling"])


@pytest.mark.slow
def test_a_sides_update_splits_into_its_parts(tmp_path):
    """`--side mapped --parts FILE` (smoke budget, a CPU): one update's parts of the side's own
    config, every one timed, into the file."""
    out = tmp_path / "parts.json"
    row = pv.side_parts("mapped", seeds=2, smoke=True, out=out)
    assert json.loads(out.read_text()) == row
    assert set(row["parts_ms"]) == {
        *("rollout", "learn", "policy_forwards"),
        *("env_steps_with_pictures", "env_steps_only", "env_steps_no_starts"),
    }
    assert all(v > 0 for v in row["parts_ms"].values()), row
    assert row["env_steps_per_update"] == 2 * row["num_envs"] * row["rollout_length"]  # 2 seeds
    assert row["physics"] == "jax" and row["deterministic_ops"] in (True, False)


def test_the_playground_side_s_memory_is_the_largest_its_seed_rows_measured():
    """Seeds trained in several processes keep each process's peaks in their rows; a row of
    before (no memory) counts for none, and a side with none measured says so (None)."""
    rows = [{"xla_peak_mib": 5, "nvidia_smi_peak_mib": None}, {}, {"xla_peak_mib": 3,
            "nvidia_smi_peak_mib": 7}]  # fmt: skip
    assert pv.largest(rows) == {"xla_peak_mib": 5, "nvidia_smi_peak_mib": 7}
    assert pv.largest([{}, {}]) == {"xla_peak_mib": None, "nvidia_smi_peak_mib": None}


def test_a_slower_hintsjax_side_reads_slower():
    playground = {"seconds": 300.0, "deterministic": [1.0, 2.0, 3.0], "device": "NVIDIA H200",
                  "seeds_run": [{"progress": [{}, {}, {}, {"training/sps": 50.0}],
                                 "device": "NVIDIA H200"}]}  # fmt: skip
    progress = [{"step": 0, "seconds": 0.0}, {"step": 100, "seconds": 10.0}]
    mapped = {"seconds": 600.0, "deterministic": [1.0, 2.0, 3.0], "progress": progress,
              "device": "NVIDIA H200"}  # fmt: skip
    line = pv.against_playground({"playground": playground, "mapped": mapped}, "mapped")
    assert "in 600 s against 300 s (2.0x slower), training 30 env steps/s" in line, line
    assert "against 50 (0.6x)" in line


def test_sides_on_other_gpus_are_not_timed_against_each_other():
    playground = {"seconds": 300.0, "deterministic": [1.0, 2.0, 3.0], "device": "NVIDIA H200"}
    mapped = {"seconds": 600.0, "deterministic": [1.0, 2.0, 3.0], "device": "NVIDIA H100"}
    line = pv.against_playground({"playground": playground, "mapped": mapped}, "mapped")
    assert "not set against Playground's: it ran on NVIDIA H100, Playground on NVIDIA H200" in line
    assert " s against " not in line and "x faster" not in line, line
    # Playground's seeds finished over two processes on two kinds of GPU: the side's entry names
    # the last one's, its seeds both
    playground["device"] = "NVIDIA H100"
    playground["seeds_run"] = [{"device": "NVIDIA H200"}, {"device": "NVIDIA H100"}]
    line = pv.against_playground({"playground": playground, "mapped": mapped}, "mapped")
    assert "it ran on NVIDIA H100, Playground on NVIDIA H100 and NVIDIA H200" in line, line
    assert " s against " not in line, line


def test_the_knob_steps_name_the_sides_in_the_record_and_order_their_returns():
    """A step is written only where both its sides ran; each says its IQMs, before then after,
    and which side's seeds return more (hand-picked returns: every mapped seed above every
    mapped_one seed, so P = 1.00, decided)."""
    results = {
        "mapped_one": {"deterministic": [10.0, 11.0, 12.0, 13.0]},
        "mapped": {"deterministic": [20.0, 21.0, 22.0, 23.0]},
    }
    lines = pv.knob_lines(results)
    assert len(lines) == 1, lines
    assert lines[0].startswith("- mapped_one -> mapped, its 3 pictures a step, not 1: IQM 11.5 [")
    assert (
        "-> 21.5 [" in lines[0]
        and "P(mapped > mapped_one) = 1.00 [1.00, 1.00]: decided" in lines[0]
    )
    assert pv.knob_lines({"defaults": results["mapped"]}) == []
    # sides not run (mapped_cnn, mapped_nets) pass their knobs on to the next step
    results["playground"] = {"deterministic": [1.0, 2.0, 3.0, 4.0]}
    line = pv.knob_lines(results)[1]
    assert line.startswith("- mapped -> playground, Brax's CNN (`ppo.encoder=brax_vision`), one ")
    assert "; a CNN of the critic's own (`ppo.critic_encoder=own`)" in line
    assert "; what is left (below): " in line
    assert "P(playground > mapped) = 0.00 [0.00, 0.00]" in line
