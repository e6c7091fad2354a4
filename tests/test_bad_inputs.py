"""Bad input for every command, from one table (tests/data/bad_inputs.yaml): each case exits 2
with one line that names what is wrong, prints no traceback and writes nothing. The run
command's command-line and settings sections run in tests/test_cli.py (through the real command
line and as Hydra hands them over); this file runs the rest: evaluate, video, expert,
quickstart, rank and generator through their `main(argv)`, and the run's folders in-process.
Writes the machine refuses (a full disk) and memory it lacks are one line too, exit 1."""

from __future__ import annotations

import errno
import os
from pathlib import Path

import jax
import pytest
import yaml

from hintsjax import evaluate, expert, generator, quickstart, rank, run, video
from hintsjax.system import errors, paths, refusals
from hintsjax.training import pipeline

TABLE = yaml.safe_load((Path(__file__).parent / "data" / "bad_inputs.yaml").read_text())
COMMANDS = {
    "evaluate": evaluate.main,
    "video": video.main,
    "expert": expert.main,
    "quickstart": quickstart.main,
    "rank": rank.main,
    "generator": generator.main,
}
# the commands of key=value arguments write into out_dir: a case must leave it unmade (a case's own
# out_dir comes after, and wins)
EXTRA = {"rank": ["out_dir={tmp}/out"], "generator": ["out_dir={tmp}/out"]}
TINY = {
    "env": "pendulum",
    "agent": "ppo_state",
    "seeds": 2,
    "eval_episodes": 3,
    "checkpoint_every": 2,
    "ppo": {
        "total_env_steps": 128,
        "num_envs": 4,
        "batch_size": 64,
        "minibatch_size": 32,
        "epochs": 1,
    },
}


@pytest.fixture(scope="module")
def places(tmp_path_factory) -> dict[str, str]:
    """The table's placeholders: a finished tiny run and folders damaged in known ways."""
    root = tmp_path_factory.mktemp("bad_inputs")
    assert run.main_from_values({**TINY, "out_dir": str(root), "name": "run"}) == 0
    config = (root / "run" / "config.yaml").read_text()
    folders = {
        "noconf": "",
        "nockpt": config,
        "badyaml": "env: [\n",
        "listyaml": "- 1\n- 2\n",
        "hints_run": config.replace("agent: ppo_state", "agent: hints"),
    }
    for name, text in folders.items():
        (root / name).mkdir()
        if text:
            (root / name / "config.yaml").write_text(text)
    (root / "file").write_text("not a folder\n")
    return {
        "run": str(root / "run"),
        "file": str(root / "file"),
        "hints": str(Path(__file__).parent / "data" / "hints"),
        **{name: str(root / name) for name in folders},
    }


def tree(folder: Path) -> dict[str, bytes]:
    return {
        str(p.relative_to(folder)): p.read_bytes() if p.is_file() else b"/"
        for p in sorted(folder.rglob("*"))
    }


def filled(text: str, places: dict[str, str], tmp_path: Path) -> str:
    """`text` with the table's placeholders filled in."""
    return text.format(**places, tmp=str(tmp_path))


def outcome(
    main, args: str, places: dict[str, str], tmp_path: Path, capsys
) -> tuple[int, list[str], str, bool]:
    """`main(args)` with the placeholders filled: (exit status, the lines on stderr, stderr, whether
    the fixture's folders and tmp_path are as they were)."""
    argv = [filled(a, places, tmp_path) for a in args.split()]
    watched = Path(places["run"]).parent
    before = (tree(watched), tree(tmp_path))
    try:
        status = main(argv)
    except SystemExit as e:  # argparse's errors exit from inside the parser
        status = e.code
    err = capsys.readouterr().err
    return status, err.strip().splitlines(), err, (tree(watched), tree(tmp_path)) == before


CASES = [(name, args, message) for name in COMMANDS for args, message in TABLE[name].items()]


@pytest.mark.parametrize("name, args, message", CASES, ids=[f"{n}: {a}" for n, a, _ in CASES])
def test_a_command_refuses_bad_input_in_one_line_and_writes_nothing(
    name, args, message, places, tmp_path, capsys
):
    extra = " ".join(EXTRA.get(name, []))
    status, lines, err, unchanged = outcome(
        COMMANDS[name], f"{extra} {args}".strip(), places, tmp_path, capsys
    )
    assert status == 2, err
    assert (
        len(lines) == 1
        and lines[0].startswith("error: ")
        and filled(message, places, tmp_path) in lines[0]
    ), lines
    assert "Traceback" not in err and unchanged


@pytest.mark.parametrize("args", list(TABLE["run_folders"]))
def test_a_run_refuses_an_out_dir_it_cannot_make(args, places, tmp_path, capsys):
    def main(argv: list[str]) -> int:
        key, value = argv[0].split("=", 1)
        return run.main_from_values({"env": "pendulum", key: value})

    status, lines, err, unchanged = outcome(main, args, places, tmp_path, capsys)
    assert status == 2, err
    assert (
        len(lines) == 1
        and lines[0].startswith("error: ")
        and filled(TABLE["run_folders"][args], places, tmp_path) in lines[0]
    ), lines
    assert "Traceback" not in err and unchanged


@pytest.mark.parametrize("args", list(TABLE["run_adapted_envs"]))
def test_a_run_on_a_playground_or_brax_task_refuses_bad_input(args, places, tmp_path, capsys):
    """An unknown Playground or Brax name (listing the valid ones), a hint file that does not
    import, a hint of the wrong width: one line, exit 2, nothing written (in-process, as Hydra
    hands the values over)."""
    pytest.importorskip(
        "mujoco_playground", reason="the Playground adapter needs the playground extra"
    )

    def main(argv: list[str]) -> int:
        return run.main_from_values(
            {"out_dir": str(tmp_path / "runs"), **dict(arg.split("=", 1) for arg in argv)}
        )

    status, lines, err, unchanged = outcome(main, args, places, tmp_path, capsys)
    assert status == 2, err
    assert (
        len(lines) == 1
        and lines[0].startswith("error: ")
        and filled(TABLE["run_adapted_envs"][args], places, tmp_path) in lines[0]
    ), lines
    assert "Traceback" not in err and unchanged


def test_a_file_written_whole_keeps_what_was_there_when_the_disk_fills(tmp_path):
    """A write that fails half-way (ENOSPC, EROFS) leaves the old file as it was and no part
    file, and is a WriteFailed naming the path (one line at the boundary, exit 1)."""
    out = tmp_path / "eval.json"
    out.write_text("old\n")

    def half_then_full(part: Path) -> None:
        part.write_text("half")
        raise OSError(errno.ENOSPC, "No space left on device")

    with pytest.raises(refusals.WriteFailed) as failed:
        paths.write_whole(out, half_then_full)
    assert failed.value.strerror == (
        f"could not write {out}: No space left on device; free space there (or write to another "
        "disk) and run again"
    )
    assert out.read_text() == "old\n" and [p.name for p in tmp_path.iterdir()] == ["eval.json"]
    paths.write_whole(out, lambda part: part.write_text("new\n"))
    assert out.read_text() == "new\n" and [p.name for p in tmp_path.iterdir()] == ["eval.json"]
    refused = refusals.machine_write(PermissionError(errno.EACCES, "Permission denied", "/x/y"))
    # outside writing_to: maybe a read
    assert refused.strerror == "could not read or write /x/y: Permission denied"
    with pytest.raises(PermissionError):  # not the machine's refusal of a write: passes as it was
        with refusals.writing_to(out):
            raise PermissionError(errno.ENOTDIR, "not this")


def _has_cuda() -> bool:
    try:
        return bool(jax.devices("cuda"))
    except RuntimeError:
        return False


@pytest.mark.parametrize(
    "platforms, command",
    [
        ("bogus", "run"),
        pytest.param("bogus", "evaluate", marks=pytest.mark.slow),
        pytest.param(
            "cuda",
            "run",
            marks=[pytest.mark.slow, pytest.mark.skipif(_has_cuda(), reason="a GPU is here")],
        ),
        pytest.param(
            "cuda",
            "evaluate",
            marks=[pytest.mark.slow, pytest.mark.skipif(_has_cuda(), reason="a GPU is here")],
        ),
    ],
)
def test_a_platform_jax_cannot_start_is_the_machines_set_up_in_one_line(
    platforms, command, tmp_path
):
    """JAX_PLATFORMS naming a platform the machine lacks (cuda without a GPU: JAX's own
    AssertionError; an unknown one: its RuntimeError) is one line naming it and what to do, exit 1,
    nothing written; it was 'a bug in hintsjax (AssertionError)'."""
    import subprocess
    import sys

    from hintsjax.settings.layers import run_config, save_run_config

    folder = tmp_path / "folder"
    folder.mkdir()
    save_run_config(folder, run_config({"env": "pendulum"}))
    args = ["env=pendulum", "out_dir=runs"] if command == "run" else [str(folder)]
    out = subprocess.run(
        [sys.executable, "-m", f"hintsjax.{command}", *args],
        cwd=tmp_path,
        env={**os.environ, "JAX_PLATFORMS": platforms, "HINTSJAX_DEBUG": "0"},
        capture_output=True,
        text=True,
        timeout=300,
    )
    lines = out.stderr.strip().splitlines()
    assert out.returncode == 1 and len(lines) == 1, out.stderr[-2000:]
    assert lines[0].startswith(
        f"error: JAX could not start a backend for JAX_PLATFORMS='{platforms}'"
    )
    assert "set JAX_PLATFORMS to one this machine has (cpu)" in lines[0]
    assert not (tmp_path / "runs").exists()


def test_an_adapter_whose_package_does_not_import_is_one_line(monkeypatch):
    """Brax (a pinned dependency) that does not import here: one line naming it and the install
    command, as Playground's absence already was; it was 'a bug (ModuleNotFoundError)'."""
    import sys

    from hintsjax import envs as registry

    monkeypatch.setitem(sys.modules, "hintsjax.envs.brax_env", None)  # import fails
    monkeypatch.delattr(registry, "brax_env", raising=False)  # (imported by an earlier test)
    with pytest.raises(
        ValueError, match="needs Brax, which does not import here .*pip install -e ."
    ):
        registry.ADAPTERS["brax"]()  # what env=brax:<name> calls first


def test_a_run_whose_folder_is_read_only_or_whose_device_runs_out_of_memory_says_so_in_one_line(
    monkeypatch, tmp_path, capsys
):
    """A run folder the disk refuses (EROFS as config.yaml is written) is one line naming the
    folder, exit 1; an allocation XLA refuses (a real RESOURCE_EXHAUSTED, 32 TiB) while training
    starts is one line naming the settings to lower, exit 1; neither is "a bug in hintsjax"."""
    import jax
    import jax.numpy as jnp

    monkeypatch.delenv(errors.DEBUG)
    values = {**TINY, "out_dir": str(tmp_path), "name": "r"}

    def read_only(run_dir, cfg):
        raise OSError(errno.EROFS, "Read-only file system")

    monkeypatch.setattr(run, "save_run_config", read_only)
    assert run.main_from_values(values) == refusals.MACHINE
    assert capsys.readouterr().err.strip().splitlines() == [
        f"error: could not write {tmp_path / 'r'}: Read-only file system"
    ]

    def too_big(*args, **kwargs):
        return jax.jit(lambda: jnp.ones((2**45,), jnp.uint8))().block_until_ready()

    monkeypatch.undo()
    monkeypatch.delenv(errors.DEBUG)
    monkeypatch.setattr(pipeline, "compile_evaluator", lambda *args, **kwargs: None)
    monkeypatch.setattr(pipeline, "start_training", too_big)
    assert run.main_from_values({**values, "name": "oom"}) == refusals.MACHINE
    lines = capsys.readouterr().err.strip().splitlines()
    assert lines == [
        f"error: the device ran out of memory (Out of memory allocating {2**45} bytes.); lower "
        f"{pipeline.TRAINING_SIZES} and run again"
    ], lines
    assert not (tmp_path / "oom" / "traceback.txt").exists()

    @errors.command
    def evaluating() -> int:  # as hintsjax.evaluate sizes its evaluation
        with refusals.sized_by("--episodes"):
            too_big()
        return 0

    assert evaluating() == refusals.MACHINE
    assert capsys.readouterr().err.strip().splitlines() == [
        f"error: the device ran out of memory (Out of memory allocating {2**45} bytes.); lower "
        "--episodes and run again"
    ]


def test_a_run_whose_compiled_program_cannot_fit_is_refused_before_training_and_leaves_nothing(
    monkeypatch, tmp_path, capsys
):
    """A device of 300 KB: the lower bounds pass (64 transitions of 16 bytes a seed), but XLA's
    memory analysis of the compiled training program (params and Adam's moments alone are MBs)
    refuses it before the first update: one line naming the settings to lower, exit 2, and the
    run folder made for it, and the out_dir folders made for that, are gone again."""
    from hintsjax.system import memory

    monkeypatch.setattr(memory, "device_bytes", lambda device=None: 300_000)
    # not this test's: its compile's time
    monkeypatch.setattr(pipeline, "compile_evaluator", lambda *args, **kwargs: None)
    assert (
        run.main_from_values({**TINY, "out_dir": str(tmp_path / "runs" / "new"), "name": "r"}) == 2
    )
    err = capsys.readouterr().err
    lines = err.strip().splitlines()
    assert (
        len(lines) == 1
        and lines[0].startswith(
            "error: seeds=2 x ppo.batch_size=64 cannot fit: training's compiled program needs "
        )
        and lines[0].endswith(
            "(XLA's memory analysis), a device has 293.0 KiB; lower ppo.batch_size (with "
            "ppo.num_envs and ppo.minibatch_size), seeds or image_size"
        )
    ), lines
    assert "Traceback" not in err and list(tmp_path.iterdir()) == []


def test_the_table_holds_at_least_120_cases_across_all_seven_commands():
    # its cases: tests/test_video.py
    commands = {name.split("_")[0] for name in TABLE} - {"unwritable"}
    assert commands == {"run", *COMMANDS} and sum(map(len, TABLE.values())) >= 120
    assert all(
        isinstance(section, dict) and all(isinstance(m, str) for m in section.values())
        for section in TABLE.values()
    )


def test_a_run_whose_folder_is_removed_while_it_trains_says_so_in_one_line(
    monkeypatch, tmp_path, capsys
):
    """The run folder removed under a training run: the next write fails (metrics.csv, once a bug
    in hintsjax), or a write makes the folder again without its config (the run exited 0 naming a
    folder that had gone). Either way one line naming the folder, exit 1."""
    import shutil

    monkeypatch.delenv(errors.DEBUG)

    def removed(cfg, run_dir, resume=False):
        shutil.rmtree(run_dir)
        (run_dir / "metrics.csv").open("a")  # as the run loop appends a chunk's rows

    def made_again(cfg, run_dir, resume=False):
        shutil.rmtree(run_dir)
        (run_dir / "checkpoints").mkdir(parents=True)  # as orbax makes its folder

    for name, trained in (("gone", removed), ("again", made_again)):
        monkeypatch.setattr(run, "train", trained)
        values = {**TINY, "out_dir": str(tmp_path), "name": name}
        assert run.main_from_values(values) == refusals.MACHINE
        error = "FileNotFoundError"
        assert capsys.readouterr().err.strip().splitlines() == [
            f"error: the run folder {tmp_path / name} was removed while the run went on ({error}); "
            "the run stopped"
        ]
