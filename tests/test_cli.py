"""The command line: bad input through the real entry points, run folders, resume, evaluate."""

from __future__ import annotations

import gc
import json
import re
import os
import shutil
import signal
import subprocess
import sys
import time
from pathlib import Path

import jax
import numpy as np
import pytest
import yaml

import command_runs
from hintsjax.system import checkpoint, errors, signals
from hintsjax.system.errors import UsageError
from hintsjax.settings import layers
from hintsjax.cli import overrides
from hintsjax.algorithms.registry import make_trainer
from hintsjax.training import loop, pipeline, request
from hintsjax import run
from hintsjax.evaluate import main as evaluate_main

# The traced-program cache on for this file's runs and the commands they start (tests/conftest.py):
# nothing here replaces a function inside a traced program (only checkpoint.save, loop.check_physics
# and run.train, outside them).
pytestmark = pytest.mark.usefixtures("traced_programs_kept")

TINY = [
    "agent=ppo_state",
    "seeds=2",
    "eval_episodes=3",
    "checkpoint_every=2",
    "checkpoint_seconds=0",
    "ppo.total_env_steps=256",
    "ppo.num_envs=4",
    "ppo.batch_size=64",
    "ppo.minibatch_size=32",
    "ppo.epochs=1",
]


def tiny_values(**extra) -> dict:
    values = {"env": "pendulum", "out_dir": "runs"}
    for item in TINY:
        key, value = item.split("=")
        target = values
        if key.startswith("ppo."):
            target = values.setdefault("ppo", {})
            key = key[4:]
        target[key] = int(value) if value.isdigit() else value
    return {**values, **extra}


def cli(*args: str, cwd: Path, module: str = "hintsjax.run") -> subprocess.CompletedProcess:
    return subprocess.run(
        [sys.executable, "-m", module, *args], cwd=cwd, capture_output=True, text=True, timeout=300
    )


def with_xla_flag(flag: str) -> str:
    """The suite's XLA_FLAGS (tests/conftest.py: LLVM's cheapest level) with `flag` added, for a
    subprocess."""
    return f"{os.environ.get('XLA_FLAGS', '')} {flag}".strip()


# every command's bad input
BAD = yaml.safe_load((Path(__file__).parent / "data" / "bad_inputs.yaml").read_text())
BAD_RUN_ARGS = BAD["run_command_line"]  # through the real command line


@pytest.fixture(scope="module")
def bad_run_outcomes(tmp_path_factory) -> dict[str, tuple[int, str, str, Path]]:
    """Every case of BAD_RUN_ARGS as `python -m hintsjax.run <case> out_dir=runs`, each in an empty
    folder of its own: (exit status, stdout, stderr, the folder). One interpreter start for them
    all (tests/command_runs.py: a child forked per case runs the module as `python -m` does);
    what importing the command prints would show on that start's stderr, which must be empty."""
    done = command_runs.outcomes(
        "hintsjax.run",
        [[*arg.split(), "out_dir=runs"] for arg in BAD_RUN_ARGS],
        tmp_path_factory.mktemp("bad_run"),
    )
    return dict(zip(BAD_RUN_ARGS, done, strict=True))


@pytest.mark.parametrize("arg", list(BAD_RUN_ARGS))
def test_bad_input_exits_2_with_one_line_and_writes_nothing(arg, bad_run_outcomes):
    returncode, stdout, stderr, folder = bad_run_outcomes[arg]
    assert returncode == 2, stderr
    lines = stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("error: "), stderr
    assert BAD_RUN_ARGS[arg] in lines[0]
    assert "Traceback" not in stderr + stdout
    assert list(folder.iterdir()) == []  # no run folder, no Hydra outputs


# The same checks in-process (no interpreter start): the imitation agents' own settings.
BAD_IMITATION_VALUES = BAD["run_imitation_settings"]


# Settings as Hydra hands them over (numbers already parsed), checked in-process: one line each.
BAD_SETTINGS = BAD["run_settings"]


def test_names_and_folders_are_strings_whatever_yaml_makes_of_them():
    """`name=2024`, `name=true`, `out_dir=123`, `resume=42` as Hydra parses them (int, bool) are
    folder names; one variant alone is a list of one."""
    assert request.folder_settings({"name": 2024, "out_dir": 123, "resume": 42}) == (
        "42",
        "123",
        "2024",
    )
    assert request.folder_settings({"name": True}) == (None, "runs", "true")
    assert request.folder_settings({}) == (None, "runs", None)
    from hintsjax.settings.layers import run_config

    assert run_config({"env": "pendulum", "eval_variants": "swingto"}).eval_variants == ("swingto",)
    assert run_config({"env": "pendulum", "ppo": {"hidden": [64]}}).ppo.hidden == (64,)


def test_a_budget_that_is_not_whole_updates_says_what_it_was_rounded_to(
    tmp_path, monkeypatch, capsys
):
    """`ppo.total_env_steps=300` with batches of 64: one line saying it trains 4 updates, 256 env
    steps a seed (it did so without a word); a whole number of updates says nothing, and neither
    does an env's own budget (the ant's 5 M in batches of 1024: the design's command)."""
    from hintsjax.settings.layers import run_config

    values = {
        k: v
        for k, v in tiny_values(ppo={**tiny_values()["ppo"], "total_env_steps": 300}).items()
        if k != "out_dir"
    }
    cfg = run_config(values)
    assert request.rounded_budget(cfg) == (
        "note: ppo.total_env_steps=300 is not a multiple of ppo.batch_size=64: "
        "trains 4 updates, 256 env steps a seed"
    )
    assert request.rounded_budget(run_config({**values, "ppo": tiny_values()["ppo"]})) is None
    monkeypatch.setattr(run, "train", lambda *args, **kwargs: None)
    assert (
        run.main_from_values(
            tiny_values(out_dir=str(tmp_path), ppo={**tiny_values()["ppo"], "total_env_steps": 300})
        )
        == 0
    )
    assert capsys.readouterr().err.strip().splitlines() == [request.rounded_budget(cfg)]
    ant = {"env": "ant", "hint": "speed", "scheme": "fc", "out_dir": str(tmp_path / "ant")}
    assert (
        request.rounded_budget(run_config({k: v for k, v in ant.items() if k != "out_dir"}))
        is not None
    )
    assert run.main_from_values(ant) == 0
    assert "note:" not in capsys.readouterr().err


def parsed(text: str):
    """A command-line value as Hydra parses it (numbers, lists, or the string)."""
    return yaml.safe_load({"nan": ".nan", "inf": ".inf"}.get(text, text))


@pytest.mark.parametrize("arg", list(BAD_SETTINGS))
def test_bad_settings_exit_2_with_one_line_and_write_nothing(arg, tmp_path, capsys):
    values = {"env": "pendulum", "out_dir": str(tmp_path / "runs")}
    for item in arg.split():
        key, text = item.split("=")
        section, _, name = key.rpartition(".")
        if section:
            values["agent"] = "gail" if section == "gail" else values.get("agent", "hints")
        (values.setdefault(section, {}) if section else values)[name or key] = parsed(text)
    assert run.main_from_values(values) == 2
    lines = capsys.readouterr().err.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("error: ") and BAD_SETTINGS[arg] in lines[0], (
        lines
    )
    assert not (tmp_path / "runs").exists()


@pytest.mark.parametrize("arg", list(BAD_IMITATION_VALUES))
def test_bad_imitation_settings_exit_2_with_one_line_and_write_nothing(arg, tmp_path, capsys):
    key, value = arg.split("=")
    values = {
        "env": "pendulum",
        "agent": "gail" if key.startswith("gail") else "dagger",
        "out_dir": str(tmp_path / "runs"),
    }
    if "." in key:
        section, key = key.split(".")
        values[section] = {key: int(value) if value.isdigit() else value}
    else:
        values[key] = value
    assert run.main_from_values(values) == 2
    lines = capsys.readouterr().err.strip().splitlines()
    assert (
        len(lines) == 1 and lines[0].startswith("error: ") and BAD_IMITATION_VALUES[arg] in lines[0]
    ), lines
    assert not (tmp_path / "runs").exists()


@pytest.mark.parametrize("argv", [["--updates", "0"], ["--updates", "-3"]])
def test_quickstart_refuses_an_empty_budget_before_writing(argv, tmp_path, capsys):
    from hintsjax import quickstart

    with pytest.raises(SystemExit) as exit_:
        quickstart.main([*argv, "--out-dir", str(tmp_path / "runs")])
    assert exit_.value.code == 2
    lines = capsys.readouterr().err.strip().splitlines()
    assert lines == [f"error: --updates must be at least 1, got {argv[1]}"]
    assert not (tmp_path / "runs").exists()


@pytest.fixture(scope="module")
def finished_run(tmp_path_factory) -> Path:
    """A complete tiny run (4 updates, checkpoints at 2 and 4), made in-process."""
    root = tmp_path_factory.mktemp("cli")
    values = tiny_values(out_dir=str(root / "runs"), name="full")
    assert run.main_from_values(values) == 0
    return root / "runs" / "full"


def state_arrays(run_dir: Path) -> list[np.ndarray]:
    """Every array of a run's newest checkpoint (params, optimiser state, env state, key,
    update)."""
    state, _ = checkpoint.restore_latest(
        run_dir, make_trainer(layers.load_run_config(run_dir)).abstract_state()
    )
    return [
        np.asarray(
            jax.random.key_data(x) if jax.dtypes.issubdtype(x.dtype, jax.dtypes.prng_key) else x
        )
        for x in jax.tree.leaves(state)
    ]


def logged_returns(run_dir: Path) -> list[tuple[str, str, str]]:
    """metrics.csv's update, seed and episode return columns, as written."""
    import csv

    with (run_dir / "metrics.csv").open() as f:
        return [(r["update"], r["seed"], r["episode_return"]) for r in csv.DictReader(f)]


def killed_run(mode: str, values: dict, cwd: Path) -> subprocess.CompletedProcess:
    """tests/killed_run.py in `mode` on a run of `values`, in a process of its own."""
    return subprocess.run(
        [sys.executable, str(Path(__file__).parent / "killed_run.py"), mode, json.dumps(values)],
        cwd=cwd,
        capture_output=True,
        text=True,
        timeout=300,
    )


def assert_ends_as(folder: Path, finished_run: Path) -> None:
    """The run in `folder` ended with `finished_run`'s state, every array equal bit for bit, and
    logged its returns."""
    for a, b in zip(state_arrays(folder), state_arrays(finished_run), strict=True):
        np.testing.assert_array_equal(a, b)
    assert logged_returns(folder) == logged_returns(finished_run)


def assert_resumes_to_the_uninterrupted_end(folder: Path, finished_run: Path, cwd: Path) -> None:
    """`python -m hintsjax.run resume=folder` succeeds and ends as the uninterrupted run did."""
    resumed = cli(f"resume={folder}", cwd=cwd)
    assert resumed.returncode == 0, resumed.stderr[-2000:]
    assert_ends_as(folder, finished_run)


# both in the slow tier (27 and 40 s on 2 cores): the default tier keeps a group killed so
# (tests/test_group.py) and a run stopped by Ctrl-C, resumed bit for bit (below)
@pytest.mark.slow
@pytest.mark.parametrize("when", ["after", "during"])
def test_a_run_killed_with_sigkill_resumes_to_the_uninterrupted_end_bit_for_bit(
    when, finished_run, tmp_path
):
    """SIGKILL once the first checkpoint is written (`after`), or while the second is being written
    in the background (`during`): the resumed run (the real command) ends with the uninterrupted
    run's state, every array equal bit for bit, and logs the same returns; a checkpoint the kill
    cut short is never read."""
    killed = killed_run(when, tiny_values(out_dir=str(tmp_path), name="killed"), tmp_path)
    assert killed.returncode == -9, killed.stderr[-2000:]
    folder = tmp_path / "killed"
    # after: the first checkpoint (update 2); during: 2, or 4 where the writer finished before
    # the kill
    assert checkpoint.latest_update(folder) in ((2,) if when == "after" else (2, 4))
    assert_resumes_to_the_uninterrupted_end(folder, finished_run, tmp_path)


@pytest.mark.parametrize(
    "mode, status, said, values",
    [
        ("interrupt", errors.INTERRUPTED, "interrupted", {}),
        # in the slow tier: SIGTERM in-process is the default tier's (the test below)
        pytest.param(
            "terminate",
            errors.TERMINATED,
            "terminated (SIGTERM)",
            {"checkpoint_seconds": 1e9},
            marks=pytest.mark.slow,
        ),
    ],
)
def test_a_stopped_run_saves_says_how_to_go_on_and_resumes_bit_for_bit(
    mode, status, said, values, finished_run, tmp_path
):
    """SIGINT (Ctrl-C, `interrupt`) once the first chunk's metrics are logged: a checkpoint is due
    (checkpoint_seconds=0), so that state is saved; SIGTERM (`terminate`: a real kill of the run's
    own process, as a scheduler's) saves it though none is due (checkpoint_seconds=1e9). Either
    way the run prints one line naming the checkpoint and the command that goes on, no traceback,
    and exits 130 (143). Resumed by the real command, it ends as the uninterrupted run did, every
    array equal bit for bit, with the same logged returns."""
    out = killed_run(mode, tiny_values(out_dir=str(tmp_path), name="stopped", **values), tmp_path)
    folder = tmp_path / "stopped"
    assert out.returncode == status == {"interrupt": 130, "terminate": 143}[mode], out.stderr[
        -2000:
    ]
    assert "Traceback" not in out.stderr + out.stdout
    assert out.stderr.strip().splitlines()[-1] == (
        f"{said}; checkpoint at update 2; go on with: python -m hintsjax.run resume={folder}"
    )
    assert checkpoint.latest_update(folder) == 2 and not (folder / "eval.json").exists()
    assert_resumes_to_the_uninterrupted_end(folder, finished_run, tmp_path)


def test_sigterm_saves_the_newest_logged_state_the_uninterrupted_runs_bit_for_bit(
    finished_run, tmp_path, monkeypatch, capsys
):
    """SIGTERM (how a cluster stops a job at its time limit or on preemption), sent to the run's
    process by a real kill once the first chunk's metrics are logged: no checkpoint is due
    (checkpoint_seconds=1e9, where Ctrl-C would save nothing), yet that state is saved; one line
    names it and the command that goes on, no traceback, exit 143; SIGTERM's handler is put back.
    The saved state is the uninterrupted run's at update 2, every array equal bit for bit, and the
    logged returns its first two updates' (from there a resumed run ends as the uninterrupted one:
    the SIGKILL and Ctrl-C tests). In-process (a real signal, the run's own handler); through a
    process of its own, resumed by the command line to the uninterrupted end: the slow tier's test
    below."""
    real_check, checks = loop.check_physics, []

    def check_then_terminate(*args):  # advance's report calls it once a chunk's metrics are logged
        real_check(*args)
        checks.append(1)
        if len(checks) == 1:
            os.kill(os.getpid(), signal.SIGTERM)

    monkeypatch.setattr(loop, "check_physics", check_then_terminate)
    before = signal.getsignal(signal.SIGTERM)
    folder = tmp_path / "terminated"
    assert (
        run.main_from_values(
            tiny_values(out_dir=str(tmp_path), name="terminated", checkpoint_seconds=1e9)
        )
        == 143
    )
    assert signal.getsignal(signal.SIGTERM) == before
    err = capsys.readouterr().err
    assert "Traceback" not in err and err.strip().splitlines()[-1] == (
        "terminated (SIGTERM); checkpoint at update 2; go on with: python -m hintsjax.run "
        f"resume={folder}"
    )
    assert checkpoint.latest_update(folder) == 2 and not (folder / "eval.json").exists()
    at_two = tmp_path / "uninterrupted_at_2"
    shutil.copytree(finished_run / "checkpoints", at_two / "checkpoints")
    shutil.rmtree(at_two / "checkpoints" / "4")
    shutil.copy(finished_run / "config.yaml", at_two)
    for a, b in zip(state_arrays(folder), state_arrays(at_two), strict=True):
        np.testing.assert_array_equal(a, b)
    assert logged_returns(folder) == [r for r in logged_returns(finished_run) if int(r[0]) <= 2]


def test_a_resume_with_damaged_small_files_repairs_them_and_ends_as_the_uninterrupted_run(
    finished_run, tmp_path, capsys
):
    """The run folder's small files as a stop while they were written leaves them: seconds.json
    empty, metrics.csv cut off in its last row after its checkpoint at update 2. The resume says
    so in one line each, goes on from the checkpoint, and ends as the uninterrupted run: the same
    logged returns and a whole eval.json (it once ended in a JSONDecodeError, a KeyError, or a
    ValueError after training)."""
    folder = tmp_path / "damaged"
    shutil.copytree(finished_run, folder)
    shutil.rmtree(folder / "checkpoints" / "4")
    (folder / "eval.json").unlink()
    (folder / "seconds.json").write_text("")
    text = (folder / "metrics.csv").read_text()
    cut = text.index("\n3,1,")  # into update 3's second row, written after the checkpoint
    (folder / "metrics.csv").write_text(text[: cut + 8])
    capsys.readouterr()
    assert run.main_from_values({"resume": str(folder)}) == 0
    err = [line for line in capsys.readouterr().err.splitlines() if line.startswith("warning")]
    assert len(err) == 1 and "seconds.json is unreadable" in err[0], err
    assert logged_returns(folder) == logged_returns(finished_run)
    assert json.loads((folder / "eval.json").read_text())["evaluations"]


# the dropped exception, as Python reports it
@pytest.mark.filterwarnings("ignore::pytest.PytestUnraisableExceptionWarning")
def test_a_sigterm_python_dropped_is_raised_again_where_training_checks():
    """A signal's exception raised while a garbage collector's callback runs (JAX has one) is
    dropped by Python ("Exception ignored in ..."): it happened to submitit's preemption signal in
    a trial. The stop is kept, raise_stop_asked (called at training's safe points) raises it
    again, and nothing is left once the block ends. Within stops_deferred (training's loop) the
    signal only keeps its stop, for the loop to raise."""

    def terminate_inside(phase, info):
        if phase == "start":
            signal.raise_signal(signal.SIGTERM)

    with signals.sigterm_as_interrupt():
        gc.callbacks.append(terminate_inside)
        try:
            gc.collect()  # the SIGTERM's Terminated is raised in the callback, and dropped
        finally:
            gc.callbacks.remove(terminate_inside)
        with pytest.raises(signals.Terminated):
            signals.raise_stop_asked()
        with pytest.raises(signals.Terminated):
            signals.raise_stop_asked()  # until the block that asked for it ends
    signals.raise_stop_asked()
    with signals.sigterm_as_interrupt():
        with signals.stops_deferred():
            signal.raise_signal(signal.SIGTERM)  # kept, not raised
            with pytest.raises(signals.Terminated):
                signals.raise_stop_asked()


@pytest.mark.filterwarnings("ignore::pytest.PytestUnraisableExceptionWarning")
@pytest.mark.parametrize(
    "sent",
    [pytest.param(signal.SIGTERM, marks=pytest.mark.slow), signal.SIGINT],
    ids=["sigterm", "ctrl-c"],
)
def test_a_stop_while_compiling_is_honoured_and_its_folder_resumes_from_the_start(
    sent, finished_run, tmp_path, monkeypatch, capsys
):
    """A signal while the run still compiles, its exception dropped by Python inside a garbage
    collector's callback (as JAX's gc callback did: "Exception ignored in ... KeyboardInterrupt",
    and the run then trained to its end), stops the run before its first state with the line
    that names the command going on (exit 143 or 130); that resume, of a folder with its config
    and no checkpoint, trains from the start and ends as the uninterrupted run, bit for bit."""
    real = loop.compile_training

    def signalled_inside(phase, info):
        if phase == "start":
            gc.callbacks.remove(signalled_inside)
            signal.raise_signal(sent)

    def compiling(*args, **kwargs):
        compiled = real(*args, **kwargs)
        gc.callbacks.append(signalled_inside)
        gc.collect()  # the signal's exception is raised in the callback, and dropped
        return compiled

    monkeypatch.setattr(loop, "compile_training", compiling)
    folder = tmp_path / "compiling"
    status = run.main_from_values(tiny_values(out_dir=str(tmp_path), name="compiling"))
    assert status == {signal.SIGTERM: 143, signal.SIGINT: 130}[sent]
    stopped = "terminated (SIGTERM)" if sent == signal.SIGTERM else "interrupted"
    assert capsys.readouterr().err.strip().splitlines()[-1] == (
        f"{stopped}; no checkpoint yet; go on with: python -m hintsjax.run resume={folder}"
    )
    assert checkpoint.latest_update(folder) is None and not (folder / "metrics.csv").exists()
    monkeypatch.setattr(loop, "compile_training", real)
    assert run.main_from_values({"resume": str(folder)}) == 0
    assert "holds no checkpoint yet (stopped before its first): it trains from the start" in (
        capsys.readouterr().err
    )
    for a, b in zip(state_arrays(folder), state_arrays(finished_run), strict=True):
        np.testing.assert_array_equal(a, b)
    assert logged_returns(folder) == logged_returns(finished_run)


@pytest.mark.parametrize("finished", [True, False], ids=["finished", "unfinished"])
def test_a_folder_that_lost_its_checkpoints_is_refused_on_resume(
    finished, finished_run, tmp_path, capsys
):
    """A folder that once saved a checkpoint (its eval.json, or the seconds.json every save
    writes) and has none now lost them: a resume is refused in one line, its log kept, where
    training from the start would have dropped it."""
    folder = tmp_path / "lost"
    shutil.copytree(finished_run, folder)
    shutil.rmtree(folder / "checkpoints")
    if not finished:
        (folder / "eval.json").unlink()
    before = {p.name: p.read_bytes() for p in folder.iterdir() if p.is_file()}
    capsys.readouterr()
    assert run.main_from_values({"resume": str(folder)}) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "its checkpoints were lost" in err[0], err
    assert {p.name: p.read_bytes() for p in folder.iterdir() if p.is_file()} == before


def test_a_second_ctrl_c_stops_at_once():
    """The first Ctrl-C is kept for a safe point (and raised there); a second, while the first is
    under way (a save, an evaluation), is raised at once: the run can always be stopped."""
    with signals.sigint_as_interrupt():
        with signals.stops_deferred():
            signal.raise_signal(signal.SIGINT)  # kept
            with pytest.raises(KeyboardInterrupt):
                signal.raise_signal(signal.SIGINT)  # at once
        with pytest.raises(KeyboardInterrupt):
            signals.raise_stop_asked()
    with signals.sigterm_as_interrupt():  # a second SIGTERM is not: the save goes on
        with signals.stops_deferred():
            signal.raise_signal(signal.SIGTERM)
            signal.raise_signal(signal.SIGTERM)


def test_a_sweep_is_expanded_in_hydras_order_with_every_value_checked_first():
    jobs = overrides.sweep_jobs(
        ["-m", "seeds=1,2", "scheme=lc,fc", "ppo.num_envs=4", "hydra/launcher=basic"]
    )
    assert [label for label, _ in jobs] == [
        "seeds=1 scheme=lc",
        "seeds=1 scheme=fc",
        "seeds=2 scheme=lc",
        "seeds=2 scheme=fc",
    ]
    values = jobs[3][1]
    assert values["seeds"] == 2 and values["scheme"] == "fc" and values["ppo"]["num_envs"] == 4
    assert (
        values["env"] == overrides.defaults()["env"]
        and values["ppo"]["epochs"] == overrides.defaults()["ppo"]["epochs"]
    )
    assert overrides.sweep_jobs(["seeds=1"]) == []  # not a sweep
    seen = []
    overrides.check_sweep(["-m", "seed=0,1"], lambda v: seen.append(v["seed"]))
    assert seen == [0, 1]
    with pytest.raises(UsageError, match="sweep job 'seed=1': no"):
        overrides.check_sweep(
            ["-m", "seed=0,1"],
            lambda v: (_ for _ in ()).throw(UsageError("no")) if v["seed"] else None,
        )


def test_help_into_a_closed_pipe_stops_quietly_with_the_shells_status(tmp_path):
    """`python -m hintsjax.run --help | head -1`: once the reader has gone, the command stops with
    nothing on stderr and exit 141 (128 + SIGPIPE, as a shell's commands do), not as a bug."""
    proc = subprocess.Popen(
        [sys.executable, "-m", "hintsjax.run", "--help"],
        cwd=tmp_path,
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
    )
    proc.stdout.close()  # the reader goes before the first line arrives
    stderr = proc.communicate(timeout=300)[1].decode()
    assert proc.returncode == errors.CLOSED_PIPE == 141 and stderr == "", stderr[-2000:]


def test_a_bug_is_one_line_saying_so_with_its_traceback_kept(monkeypatch, tmp_path, capsys):
    """Anything but bad input that escapes a command is a bug in hintsjax: one line saying so and
    where its traceback went (the run folder, for a run), exit 1; with HINTSJAX_DEBUG set, Python's
    own traceback instead. argparse's usage errors are one line too."""
    from hintsjax.system import errors
    from hintsjax import evaluate

    monkeypatch.delenv(errors.DEBUG)

    def boom(*args, **kwargs):
        raise RuntimeError("boom\nsecond line")

    monkeypatch.setattr(run, "train", boom)
    assert run.main_from_values(tiny_values(out_dir=str(tmp_path), name="r")) == 1
    lines = capsys.readouterr().err.strip().splitlines()
    assert lines == [
        "error: a bug in hintsjax (RuntimeError: boom); its traceback is in "
        f"{tmp_path / 'r' / 'traceback.txt'}; please report it with that traceback"
    ]
    kept = (tmp_path / "r" / "traceback.txt").read_text()
    assert kept.startswith("Traceback") and "in boom" in kept and "second line" in kept

    monkeypatch.setattr(evaluate, "load_run_config", boom)
    assert evaluate.main([str(tmp_path / "r")]) == 1
    line = capsys.readouterr().err.strip()
    assert "\n" not in line and "a bug in hintsjax (RuntimeError: boom)" in line
    assert "boom" in Path(line.split("its traceback is in ")[1].split(";")[0]).read_text()

    monkeypatch.setenv(errors.DEBUG, "1")
    with pytest.raises(RuntimeError, match="boom"):
        evaluate.main([str(tmp_path / "r")])
    with pytest.raises(SystemExit) as exited:
        evaluate.main([str(tmp_path / "r"), "--nope"])
    assert exited.value.code == 2
    assert capsys.readouterr().err.strip().splitlines() == [
        "error: unrecognized arguments: --nope; see python -m hintsjax.evaluate --help"
    ]


def test_a_checkpoint_that_cannot_be_written_is_the_one_named(tmp_path):
    """The file-size limit (as a disk that fills up) hit while the first checkpoint (update 2) is
    written in the background: the run stops with exit 1 and its last line names that checkpoint
    and its folder (the failure surfaces when the next one is handed over, update 4, which the
    message named before), nothing else is printed but the progress bar, and nothing takes the
    half-written one for complete."""
    command = " ".join(
        [
            sys.executable,
            "-m",
            "hintsjax.run",
            "env=pendulum",
            *TINY,
            "out_dir=runs",
            "name=full",
            "compilation_cache=false",
        ]
    )
    # ulimit -f: the KiB a file may hold; config.yaml and metrics.csv fit, the checkpoint's arrays
    # do not
    out = subprocess.run(
        ["bash", "-c", f"ulimit -f 100 && exec {command}"],
        cwd=tmp_path,
        capture_output=True,
        text=True,
        timeout=300,
    )
    folder = (tmp_path / "runs" / "full").absolute()
    assert out.returncode == 1, out.stderr[-2000:]
    said = command_runs.said(out.stderr)
    # no "Event loop is closed" traces from orbax's closed loop before it
    assert len(said) == 1, said[:12]
    assert said[0].startswith(
        f"error: could not write checkpoint 2 in {folder / 'checkpoints'}: "
    ), said[0]
    assert checkpoint.latest_update(folder) is None


def test_run_folder_holds_everything(finished_run):
    names = {p.name for p in finished_run.iterdir()}
    assert {
        "config.yaml",
        "metrics.csv",
        "tb",
        "checkpoints",
        "eval.json",
        "learning_curve.png",
    } <= names
    assert any(p.name.startswith("events") for p in (finished_run / "tb").iterdir())
    config = yaml.safe_load((finished_run / "config.yaml").read_text())
    assert config["agent"] == "ppo_state" and config["ppo"]["total_env_steps"] == 256
    results = json.loads((finished_run / "eval.json").read_text())
    # on a CPU every op repeats
    assert results["deterministic"] is True and results["physics"] == "jax"
    split = results["wall_split_seconds"]  # where the call's wall-clock went, stage by stage
    assert list(split) == ["startup", "before_training", "training", "evaluation"] and all(
        v >= 0 for v in split.values()
    )
    # the compile is part of it
    assert split["before_training"] >= results["compile_seconds"]["train"]
    assert split["training"] >= results["train_seconds_this_call"]
    variants = [e["variant"] for e in results["evaluations"]]
    assert variants == ["swingup", "swingto"]  # the training task, then pendulum's deploy variant
    for e in results["evaluations"]:
        returns = np.array(e["returns"])
        assert returns.shape == (2, 3)
        assert np.isclose(e["mean"], returns.mean()) and np.all(returns < 0)
    rows = (finished_run / "metrics.csv").read_text().strip().splitlines()
    assert len(rows) == 1 + 4 * 2  # header + 4 updates x 2 seeds
    assert checkpoint.latest_update(finished_run) == 4


def test_a_saved_config_reads_back_as_trained_whatever_todays_env_defaults(tmp_path):
    # The ant's learners take a KL early stop and rates adapted to the KL by default, its references
    # neither; a run trained without them (null and false in its config.yaml) must read back
    # without them, not with today's defaults.
    from dataclasses import replace

    from hintsjax.settings.layers import load_run_config, run_config, save_run_config

    assert run_config({"env": "ant", "agent": "hints"}).ppo.target_kl == 0.05
    assert run_config({"env": "ant", "agent": "hints"}).ppo.kl_adaptive_lr
    assert run_config({"env": "ant", "agent": "expert_ppo"}).ppo.target_kl is None
    assert not run_config({"env": "ant", "agent": "expert_ppo"}).ppo.kl_adaptive_lr
    cfg = run_config({"env": "ant", "agent": "hints"})
    old = replace(cfg, ppo=replace(cfg.ppo, target_kl=None, kl_adaptive_lr=False))
    save_run_config(tmp_path, old)
    assert load_run_config(tmp_path) == old
    save_run_config(tmp_path, cfg)
    assert load_run_config(tmp_path) == cfg


def test_checkpoint_seconds_spaces_the_checkpoints_and_keeps_the_last(tmp_path, monkeypatch):
    """With checkpoint_seconds longer than the run, only the last update is saved; every update
    is still logged."""
    saved, real_save = [], checkpoint.save
    monkeypatch.setattr(
        checkpoint,
        "save",
        lambda run_dir, state, update: (saved.append(update), real_save(run_dir, state, update)),
    )
    assert (
        run.main_from_values(
            tiny_values(out_dir=str(tmp_path), name="spaced", checkpoint_seconds=1e9)
        )
        == 0
    )
    assert saved == [4]
    assert json.loads((tmp_path / "spaced" / loop.SECONDS_JSON).read_text())["update"] == 4
    assert len((tmp_path / "spaced" / "metrics.csv").read_text().strip().splitlines()) == 1 + 4 * 2
    assert (
        run.main_from_values(tiny_values(out_dir=str(tmp_path), name="bad", checkpoint_seconds=-1))
        == 2
    )
    assert not (tmp_path / "bad").exists()


def test_interrupted_then_resumed_run_ends_where_the_uninterrupted_one_ends(
    finished_run, tmp_path, monkeypatch
):
    values = tiny_values(out_dir=str(tmp_path), name="interrupted")
    real_save = checkpoint.save

    def save_then_crash(run_dir, state, update):
        real_save(run_dir, state, update)
        raise KeyboardInterrupt  # the process dies right after its first checkpoint

    monkeypatch.setattr(checkpoint, "save", save_then_crash)
    # the interrupt is one line and exit 130
    assert run.main_from_values(dict(values)) == errors.INTERRUPTED
    monkeypatch.setattr(checkpoint, "save", real_save)
    interrupted = tmp_path / "interrupted"
    assert checkpoint.latest_update(interrupted) == 2

    assert run.main_from_values({"resume": str(interrupted)}) == 0
    cfg = layers.load_run_config(interrupted)
    resumed, step = checkpoint.restore_latest(interrupted, make_trainer(cfg).abstract_state())
    full, full_step = checkpoint.restore_latest(finished_run, make_trainer(cfg).abstract_state())
    assert step == full_step == 4
    for a, b in zip(jax.tree.leaves(resumed.params), jax.tree.leaves(full.params)):
        np.testing.assert_allclose(np.asarray(a), np.asarray(b), rtol=1e-6, atol=1e-7)
    np.testing.assert_array_equal(jax.random.key_data(resumed.key), jax.random.key_data(full.key))
    # the metrics file has each update exactly once
    rows = (interrupted / "metrics.csv").read_text().strip().splitlines()
    assert len(rows) == 1 + 4 * 2
    full_eval = json.loads((finished_run / "eval.json").read_text())["evaluations"][0]["mean"]
    resumed_eval = json.loads((interrupted / "eval.json").read_text())["evaluations"][0]["mean"]
    assert np.isclose(full_eval, resumed_eval, rtol=1e-5)


def test_evaluate_command_on_a_deploy_variant(finished_run, capsys):
    assert evaluate_main([str(finished_run), "--variant", "swingto", "--episodes", "4"]) == 0
    written = json.loads((finished_run / "eval-swingto-deterministic-4.json").read_text())
    assert written["variant"] == "swingto" and np.array(written["returns"]).shape == (2, 4)
    assert "swingto" in capsys.readouterr().out


def test_evaluate_command_on_two_variants_in_one_program(finished_run, capsys):
    """--variant a,b writes each variant's file, equal to evaluating it alone."""
    assert (
        evaluate_main(
            [str(finished_run), "--variant", "swingup,swingto", "--episodes", "4", "--stochastic"]
        )
        == 0
    )
    both = {
        v: json.loads((finished_run / f"eval-{v}-stochastic-4.json").read_text())
        for v in ("swingup", "swingto")
    }
    assert (
        evaluate_main(
            [str(finished_run), "--variant", "swingto", "--episodes", "4", "--stochastic"]
        )
        == 0
    )
    alone = json.loads((finished_run / "eval-swingto-stochastic-4.json").read_text())
    assert (
        both["swingto"]["returns"] == alone["returns"]
        and both["swingup"]["returns"] != alone["returns"]
    )
    assert evaluate_main([str(finished_run), "--variant", "swingup,nope"]) == 2
    assert "valid choices: swingto, swingup" in capsys.readouterr().err


def test_evaluate_command_samples_as_the_run_does_unless_told(finished_run, tmp_path):
    """Without --stochastic or --deterministic, hintsjax.evaluate follows the run's stochastic_eval
    (the car's default samples); either flag overrides it, and the two together are refused."""
    import shutil

    import yaml

    sampled_run = tmp_path / "sampled"
    shutil.copytree(finished_run, sampled_run)
    values = yaml.safe_load((sampled_run / "config.yaml").read_text())
    assert values["stochastic_eval"] is False
    (sampled_run / "config.yaml").write_text(
        yaml.safe_dump({**values, "stochastic_eval": True}, sort_keys=False)
    )
    args = ["--variant", "swingto", "--episodes", "4"]
    assert evaluate_main([str(sampled_run), *args]) == 0
    default = json.loads((sampled_run / "eval-swingto-stochastic-4.json").read_text())
    assert evaluate_main([str(finished_run), *args, "--stochastic"]) == 0
    assert (
        default["returns"]
        == json.loads((finished_run / "eval-swingto-stochastic-4.json").read_text())["returns"]
    )
    assert evaluate_main([str(sampled_run), *args, "--deterministic"]) == 0
    assert evaluate_main([str(finished_run), *args]) == 0
    deterministic = [
        json.loads((run / "eval-swingto-deterministic-4.json").read_text())["returns"]
        for run in (sampled_run, finished_run)
    ]
    assert deterministic[0] == deterministic[1] != default["returns"]
    with pytest.raises(SystemExit):
        evaluate_main([str(sampled_run), "--stochastic", "--deterministic"])


def test_evaluate_bad_inputs(finished_run, tmp_path, capsys):
    assert evaluate_main([str(tmp_path / "missing")]) == 2
    assert evaluate_main([str(finished_run), "--variant", "nope"]) == 2
    assert "valid choices: swingto, swingup" in capsys.readouterr().err
    assert evaluate_main([str(finished_run), "--episodes", "0"]) == 2
    # 3.8 TiB of activations at least
    assert evaluate_main([str(finished_run), "--episodes", str(2 * 10**9)]) == 2
    assert (
        f"--episodes={2 * 10**9} cannot fit: evaluating 2 seeds x {2 * 10**9} episodes"
        in capsys.readouterr().err
    )
    with pytest.raises(SystemExit) as exited:  # beyond int32: argparse's one line
        evaluate_main([str(finished_run), "--episodes", str(10**12)])
    assert exited.value.code == 2 and "must be at most 2147483647" in capsys.readouterr().err
    empty = tmp_path / "no_checkpoint"
    empty.mkdir()
    shutil.copy(finished_run / "config.yaml", empty / "config.yaml")
    assert evaluate_main([str(empty)]) == 2
    assert "no checkpoint" in capsys.readouterr().err


def test_a_checkpoint_saved_on_another_device_restores_here(finished_run, tmp_path):
    """A run's checkpoint names the devices it was saved from (a GPU's, say); restoring onto a
    machine that lacks them gives the same state on this machine's device."""
    copy = tmp_path / "moved"
    shutil.copytree(finished_run, copy)
    shutil.rmtree(copy / "checkpoints")
    script = (  # a second CPU device stands in for a device this process lacks
        "import sys, jax\n"
        "from hintsjax.system import checkpoint\n"
        "from hintsjax.settings import layers\n"
        "from hintsjax.algorithms.registry import make_trainer\n"
        f"src, dest = {str(finished_run)!r}, {str(copy)!r}\n"
        "state, update = checkpoint.restore_latest(src, "
        "make_trainer(layers.load_run_config(src)).abstract_state())\n"
        "checkpoint.save(dest, jax.device_put(state, jax.devices()[1]), update)\n"
    )
    env = {
        **os.environ,
        "JAX_PLATFORMS": "cpu",
        "XLA_FLAGS": with_xla_flag("--xla_force_host_platform_device_count=2"),
    }
    out = subprocess.run(
        [sys.executable, "-c", script], env=env, capture_output=True, text=True, timeout=300
    )
    assert out.returncode == 0, out.stderr[-2000:]
    assert len(jax.devices()) == 1
    cfg = layers.load_run_config(finished_run)
    moved, update = checkpoint.restore_latest(copy, make_trainer(cfg).abstract_state())
    original, _ = checkpoint.restore_latest(finished_run, make_trainer(cfg).abstract_state())
    assert update == 4
    for a, b in zip(jax.tree.leaves(original), jax.tree.leaves(moved)):
        if jax.dtypes.issubdtype(a.dtype, jax.dtypes.prng_key):
            a, b = jax.random.key_data(a), jax.random.key_data(b)
        np.testing.assert_array_equal(np.asarray(a), np.asarray(b))
        assert b.devices() == {jax.devices()[0]}


def test_mismatched_checkpoint_is_refused(finished_run, tmp_path):
    copy = tmp_path / "mismatched"
    shutil.copytree(finished_run, copy)
    config = yaml.safe_load((copy / "config.yaml").read_text())
    config["ppo"]["hidden"] = [32, 32]  # the saved params are 256 wide
    (copy / "config.yaml").write_text(yaml.safe_dump(config))
    before = sorted(p.name for p in copy.rglob("*"))
    # Refused from the stored shapes, before any array is read.
    with pytest.raises(
        UsageError, match=r"does not match its config.yaml: its \d+ arrays differ in shape"
    ):
        checkpoint.restore_latest(copy, make_trainer(layers.load_run_config(copy)).abstract_state())
    assert sorted(p.name for p in copy.rglob("*")) == before  # nothing written or removed


def test_corrupt_checkpoints_are_refused_through_the_command_line(finished_run, tmp_path):
    """Every checkpoint garbage (the newest alone falls back: the next test): one line naming the
    newest, exit 2, for evaluate and for resume, and nothing rewritten."""
    copy = tmp_path / "corrupt"
    shutil.copytree(finished_run, copy)
    for f in (copy / "checkpoints").rglob("*"):
        if f.is_file():
            f.write_bytes(b"\0garbage")
    metrics_before = (copy / "metrics.csv").read_text()
    out = cli(str(copy), cwd=tmp_path, module="hintsjax.evaluate")
    assert out.returncode == 2 and "Traceback" not in out.stderr
    assert (
        out.stderr.strip().startswith("error: checkpoint 4")
        and len(out.stderr.strip().splitlines()) == 1
    )
    out = cli(f"resume={copy}", cwd=tmp_path)
    assert out.returncode == 2 and "Traceback" not in out.stderr, out.stderr
    assert (copy / "metrics.csv").read_text() == metrics_before


def corrupted(step: Path, how: str) -> None:
    """Checkpoint folder `step` damaged as a crash leaves it: array files cut short (`truncated`),
    its OCDBT manifests gone (`no_manifest`), every file renamed into place but its data never
    flushed, as after a power cut (`zeroed`), or its array metadata gone (`no_metadata`)."""
    if how == "truncated":
        for f in (step / "default" / "ocdbt.process_0" / "d").iterdir():
            f.write_bytes(f.read_bytes()[: f.stat().st_size // 2])
    elif how == "no_manifest":
        for f in step.rglob("manifest.ocdbt"):
            f.unlink()
    elif how == "zeroed":
        for f in [f for f in step.rglob("*") if f.is_file()]:
            f.write_bytes(b"")
    elif how == "no_metadata":
        (step / "default" / "_METADATA").unlink()
    else:
        raise ValueError(how)


def test_a_corrupt_newest_checkpoint_falls_back_to_the_one_before_and_resumes_bit_for_bit(
    finished_run, tmp_path, capsys
):
    """Checkpoint 4 damaged four ways a crash leaves one: each restore passes it over for
    checkpoint 2 (its arrays exactly those of checkpoint 2 read while whole) with one line naming
    both; resumed through the run command, the run sets 4 aside (checkpoints-corrupt/), trains
    2 -> 4 again and ends as the uninterrupted run did, every array equal bit for bit, with the
    same logged returns; a stray empty checkpoint folder beside them does not block it."""
    cfg = layers.load_run_config(finished_run)
    abstract = make_trainer(cfg).abstract_state()
    whole = tmp_path / "whole"
    shutil.copytree(finished_run, whole)
    shutil.rmtree(whole / "checkpoints" / "4")
    two = state_arrays(whole)
    for how in ("truncated", "no_manifest", "zeroed", "no_metadata"):
        copy = tmp_path / how
        shutil.copytree(finished_run, copy)
        corrupted(copy / "checkpoints" / "4", how)
        capsys.readouterr()
        state, update = checkpoint.restore_latest(copy, abstract)
        lines = capsys.readouterr().err.strip().splitlines()
        assert update == 2 and len(lines) == 1, (how, lines)
        assert lines[0].startswith(
            f"warning: checkpoint 4 in {copy / 'checkpoints'} cannot be restored ("
        ) and lines[0].endswith("); using checkpoint 2, the newest that restores"), lines
        restored = [
            np.asarray(
                jax.random.key_data(x) if jax.dtypes.issubdtype(x.dtype, jax.dtypes.prng_key) else x
            )
            for x in jax.tree.leaves(state)
        ]
        for a, b in zip(restored, two, strict=True):
            np.testing.assert_array_equal(a, b)
        assert (copy / "checkpoints" / "4").exists()  # only a run that trains on sets it aside
    # and a stray empty folder (made by hand) is no checkpoint
    (copy / "checkpoints" / "99").mkdir()
    assert run.main_from_values({"resume": str(copy)}) == 0
    assert not (copy / "checkpoints" / "99").exists()
    assert (
        f"using checkpoint 2, the newest that restores; set aside in {copy / checkpoint.CORRUPT}"
        in capsys.readouterr().err
    )
    assert [p.name.split("-")[0] for p in (copy / checkpoint.CORRUPT).iterdir()] == ["4"]
    assert_ends_as(copy, finished_run)


def test_a_stray_empty_checkpoint_folder_is_no_checkpoint(finished_run, tmp_path):
    """An empty checkpoints/99 (made by hand) is no checkpoint: the newest is the real 4, and the
    empty folder is gone (a run resumes past one: the corrupt checkpoint's test above)."""
    copy = tmp_path / "stray"
    shutil.copytree(finished_run, copy)
    (copy / "checkpoints" / "99").mkdir()
    assert checkpoint.latest_update(copy) == 4 and not (copy / "checkpoints" / "99").exists()


@pytest.mark.parametrize(
    "garbage", [b"not,a,metrics\nfile,at,all\n", b"update,seed\nfour,0\n", b"\xff\xfe\x00"]
)
def test_a_garbage_metrics_file_is_one_line_and_kept(garbage, finished_run, tmp_path):
    copy = tmp_path / "garbage"
    shutil.copytree(finished_run, copy)
    shutil.rmtree(copy / "checkpoints" / "4")  # resume from 2: the rows after it would be dropped
    (copy / "eval.json").unlink()
    (copy / "metrics.csv").write_bytes(garbage)
    with pytest.raises(UsageError, match="metrics.csv is not a metrics file of this run"):
        pipeline.train(layers.load_run_config(copy), copy, resume=True, progress=False)
    assert (copy / "metrics.csv").read_bytes() == garbage


def test_a_config_that_is_not_utf8_is_one_line(finished_run, tmp_path):
    copy = tmp_path / "latin1"
    shutil.copytree(finished_run, copy)
    (copy / "config.yaml").write_bytes((copy / "config.yaml").read_bytes() + b"# \xe9t\xe9\n")
    with pytest.raises(UsageError, match="cannot read .*config.yaml: UnicodeDecodeError"):
        layers.load_run_config(copy)


def test_a_resumed_run_trains_longer_to_the_longer_runs_end_bit_for_bit(
    finished_run, tmp_path, capsys
):
    """A run of 2 updates, resumed through the command line with the 4-update budget of
    `finished_run`, ends with its state bit for bit and its logged returns; its config.yaml says
    the new budget. A smaller budget is one line and leaves the folder alone (in-process: the
    command line's parse of the same two settings is the longer resume's)."""
    short = tmp_path / "short"
    assert (
        run.main_from_values(
            tiny_values(
                out_dir=str(tmp_path),
                name="short",
                ppo={**tiny_values()["ppo"], "total_env_steps": 128},
            )
        )
        == 0
    )
    assert checkpoint.latest_update(short) == 2
    capsys.readouterr()
    before = sorted((p.relative_to(short), p.stat().st_mtime_ns) for p in short.rglob("*"))
    assert run.main_from_values({"resume": str(short), "ppo": {"total_env_steps": 64}}) == 2
    assert capsys.readouterr().err.strip().splitlines() == [
        "error: a resumed run can train longer, not shorter: ppo.total_env_steps must be at least "
        "128 (its budget), got 64"
    ]
    assert sorted((p.relative_to(short), p.stat().st_mtime_ns) for p in short.rglob("*")) == before
    longer = cli(f"resume={short}", "ppo.total_env_steps=256", cwd=tmp_path)
    assert longer.returncode == 0, longer.stderr[-2000:]
    assert layers.load_run_config(short) == layers.load_run_config(finished_run)
    assert_ends_as(short, finished_run)
    assert (
        json.loads((short / "eval.json").read_text())["evaluations"]
        == json.loads((finished_run / "eval.json").read_text())["evaluations"]
    )


CUTS = ("ppo.clip_eps", "eval_episodes", "gail")


@pytest.fixture(scope="module")
def cut_resumes(finished_run, tmp_path_factory) -> dict[str, tuple[int, str, Path, list[Path]]]:
    """`python -m hintsjax.run resume=<copy>` on a copy of `finished_run` whose config.yaml lacks
    each of CUTS, one interpreter start for the three (tests/command_runs.py): (exit status,
    stderr, the copy, its files before)."""
    root = tmp_path_factory.mktemp("cut")
    copies, befores = [], []
    for k, cut in enumerate(CUTS):
        copy = root / f"cut{k}"
        shutil.copytree(finished_run, copy)
        values = yaml.safe_load((copy / "config.yaml").read_text())
        section, _, key = cut.rpartition(".")
        del (values[section] if section else values)[key]
        (copy / "config.yaml").write_text(yaml.safe_dump(values))
        copies.append(copy)
        befores.append(sorted(p.relative_to(copy) for p in copy.rglob("*")))
    done = command_runs.outcomes("hintsjax.run", [[f"resume={copy}"] for copy in copies], root)
    return {
        cut: (status, err, copy, before)
        for cut, (status, _, err, _), copy, before in zip(CUTS, done, copies, befores, strict=True)
    }


@pytest.mark.parametrize("cut", CUTS)
def test_a_config_that_lacks_a_setting_is_not_resumed(cut, cut_resumes):
    """A config.yaml cut short (or from an older version) resumes under no guessed defaults: one
    line naming what it lacks, exit 2, the run folder as it was."""
    returncode, stderr, copy, before = cut_resumes[cut]
    assert returncode == 2 and len(stderr.strip().splitlines()) == 1, stderr
    assert "lacks " + (cut if cut != "gail" else "gail.") in stderr
    assert sorted(p.relative_to(copy) for p in copy.rglob("*")) == before
    assert layers.load_run_config(copy).env == "pendulum"  # reports still read it


@pytest.mark.slow  # 19 s; tests/test_devices.py's slow tests shard over four devices in-process
def test_seeds_sharded_over_two_devices_give_the_single_device_result(finished_run, tmp_path):
    env = {**os.environ, "XLA_FLAGS": with_xla_flag("--xla_force_host_platform_device_count=2")}
    args = [*TINY, "out_dir=runs", "name=sharded"]
    out = subprocess.run(
        [sys.executable, "-m", "hintsjax.run", *args],
        cwd=tmp_path,
        env=env,
        capture_output=True,
        text=True,
        timeout=300,
    )
    assert out.returncode == 0, out.stderr
    # the pendulum's MJX physics: auto on a CPU
    assert "on 2 cpu device(s) (1 a device), jax physics, compiled in" in out.stdout
    # the first line comes before anything compiles (and the cache is on, as the command line turns
    # it on)
    assert out.stdout.splitlines()[0].endswith(
        ": compiling its programs (later runs on this machine load most of them from the cache)"
    )
    sharded = json.loads((tmp_path / "runs" / "sharded" / "eval.json").read_text())["evaluations"]
    single = json.loads((finished_run / "eval.json").read_text())["evaluations"]
    for a, b in zip(sharded, single):
        np.testing.assert_allclose(a["returns"], b["returns"], rtol=1e-4)


def test_a_launcher_whose_plugin_is_missing_is_one_line(monkeypatch):
    monkeypatch.setitem(overrides.LAUNCHERS, "submitit_slurm", "hydra_plugins.no_such_launcher")
    with pytest.raises(
        UsageError,
        match=(
            r"hydra/launcher=submitit_slurm needs hydra-submitit-launcher: "
            r"pip install -e '\.\[cluster\]'"
        ),
    ):
        overrides.check_overrides(["-m", "hydra/launcher=submitit_slurm", "scheme=lc,fc"])


# 32 s on 2 cores: in the slow tier beside the requeue test, to keep `make test` within its minutes
@pytest.mark.slow
def test_a_sweep_runs_through_hydras_submitit_launcher(tmp_path):
    """`-m hydra/launcher=submitit_local`: submitit starts each job of the sweep as a process of
    its own (as submitit_slurm submits it to SLURM), and each writes its own run folder, though
    both ask for the same name at once."""
    out = cli(
        "-m",
        "hydra/launcher=submitit_local",
        "env=pendulum",
        *TINY,
        "seed=0,1",
        "out_dir=runs",
        cwd=tmp_path,
    )
    assert out.returncode == 0, out.stderr[-3000:]
    folders = [
        p for p in (tmp_path / "runs").iterdir() if p.is_dir() and not p.name.startswith(".")
    ]
    assert len(folders) == 2 and (tmp_path / "runs" / "multirun.yaml").exists()
    seeds = sorted(yaml.safe_load((f / "config.yaml").read_text())["seed"] for f in folders)
    assert seeds == [0, 1] and all(
        json.loads((f / "eval.json").read_text())["evaluations"] for f in folders
    )


def submitit_task(folder: Path) -> int | None:
    """The process id of a submitit job's task (`python -m submitit.core._submit <folder>/...`),
    or None while there is none."""
    for proc in Path("/proc").iterdir():
        try:
            words = (proc / "cmdline").read_bytes().split(b"\0")
        except OSError:  # not a process, or one that has just ended
            continue
        if b"submitit.core._submit" in words and any(str(folder).encode() in w for w in words):
            return int(proc.name)
    return None


@pytest.mark.slow  # two starts of a submitit job and a run to compare with: about 60 s on 2 cores
def test_a_preempted_submitit_job_is_requeued_and_goes_on_in_its_folder_bit_for_bit(tmp_path):
    """A sweep's job under Hydra's submitit launcher (local executor) sent submitit's preemption
    signal (SIGUSR2) once it has a checkpoint, as SLURM's would be: the run saves its newest
    logged state, submitit requeues the job, and the requeued job goes on in the same folder (its
    job.json names the job), ending as the uninterrupted run does, every array bit for bit."""
    longer = {"checkpoint_every": 10, "ppo": {**tiny_values()["ppo"], "total_env_steps": 64 * 400}}
    whole = tiny_values(out_dir=str(tmp_path / "whole"), name="run", **longer)
    assert run.main_from_values(whole) == 0
    sweep = tmp_path / "sweep"
    args = [f"{k}={v}" for k, v in whole.items() if k not in ("ppo", "out_dir")]
    args += [f"ppo.{k}={v}" for k, v in whole["ppo"].items()]
    job = subprocess.Popen(
        [
            sys.executable,
            "-m",
            "hintsjax.run",
            "-m",
            "hydra/launcher=submitit_local",
            *args,
            f"out_dir={sweep}",
        ],
        cwd=tmp_path,
        stdout=subprocess.DEVNULL,
        stderr=subprocess.DEVNULL,
    )
    folder = sweep / "run"
    while job.poll() is None and not any(
        p.name.isdigit() for p in (folder / "checkpoints").glob("*")
    ):
        time.sleep(0.02)
    task = submitit_task(sweep)
    assert task is not None, "the job ended before its first checkpoint was written"
    os.kill(task, signal.SIGUSR2)
    assert job.wait(timeout=300) == 0
    assert sorted(p.name for p in sweep.iterdir() if not p.name.startswith(".")) == [
        "multirun.yaml",
        "run",
    ]
    said = "\n".join(p.read_text() for p in (sweep / ".submitit").rglob("*_log.err"))
    job_id = json.loads((folder / "job.json").read_text())["job_id"]
    assert re.search(
        r"preempted \(SIGUSR2\); checkpoint at update \d+; submitit is asked to requeue job "
        rf"{job_id}, which goes on in {re.escape(str(folder))}",
        said,
    ), said[-3000:]
    assert f"requeued job {job_id}: goes on in" in said
    assert_ends_as(folder, tmp_path / "whole" / "run")


def test_a_preemption_that_submitit_will_not_requeue_says_so_and_names_the_command(
    monkeypatch, tmp_path, capsys
):
    """submitit refuses to requeue a job that timed out more often than max_num_timeout allows
    (its handler raises UncompletedJobError): after the line that asked, one line says so and names
    the command that goes on; exit 143. Outside a submitit job a run writes no job.json."""
    # submitit's import configures logging (dictConfig), which closes the handlers that pytest's
    # capture set up
    monkeypatch.setenv("SUBMITIT_LOG_LEVEL", "NOCONFIG")
    from submitit.core.utils import UncompletedJobError

    from hintsjax.system import requeue

    folder = tmp_path / "runs" / "run"
    folder.mkdir(parents=True)
    assert requeue.job_id() is None and requeue.folders_of_this_job(folder.parent) == []
    requeue.record(folder)
    assert not (folder / requeue.JOB_JSON).exists()
    monkeypatch.setenv("SUBMITIT_EXECUTOR", "local")
    monkeypatch.setenv("SUBMITIT_LOCAL_JOB_ID", "4242")

    def refuse():
        raise UncompletedJobError("Job not requeued because: timed-out too many times.")

    assert (
        requeue.hand_over(requeue.Preempted("SIGUSR2", refuse), folder, "checkpoint at update 2")
        == errors.TERMINATED
    )
    assert capsys.readouterr().err.splitlines() == [
        "preempted (SIGUSR2); checkpoint at update 2; submitit is asked to requeue job 4242, "
        f"which goes on in {folder}",
        f"submitit did not requeue job 4242 (Job not requeued because: timed-out too many times.); "
        f"go on with: python -m hintsjax.run resume={folder}",
    ]
    requeue.record(folder)
    assert requeue.folders_of_this_job(folder.parent) == [folder]
    # another job (or the same id on another cluster)
    monkeypatch.setenv("SUBMITIT_LOCAL_JOB_ID", "4243")
    assert requeue.folders_of_this_job(folder.parent) == []


@pytest.mark.slow
@pytest.mark.parametrize("env", ["acrobot", "idp"])
def test_classic_envs_train_from_the_command_line(env, tmp_path):
    """Every env runs through the same learner: a pixel agent with the mask scheme, end to end
    (slow: compiling an MJX env inside the trainer takes one to two minutes on 2 CPU cores)."""
    values = tiny_values(
        env=env, agent="hints", scheme="mc", hint="composite", out_dir=str(tmp_path), name="r"
    )
    assert run.main_from_values(values) == 0
    result = json.loads((tmp_path / "r" / "eval.json").read_text())
    assert result["env"] == env and np.isfinite(result["evaluations"][0]["mean"])


def test_the_checkout_runs_without_the_editable_installs_finder():
    """After a normal `pip install .`, a command run from the checkout's root imports the
    checkout's hintsjax/, which has no envs/ (pyproject maps hintsjax.envs to the top-level envs/).
    Simulated here by starting Python without site processing (no editable finder), with
    site-packages as a plain path (PYTHONPATH, after the checkout's root): hintsjax.envs must still
    import."""
    import site

    root = Path(__file__).resolve().parents[1]
    env = {**os.environ, "PYTHONPATH": site.getsitepackages()[0]}
    out = subprocess.run(
        [sys.executable, "-S", "-m", "hintsjax.run", "env=nope"],
        cwd=root,
        env=env,
        capture_output=True,
        text=True,
        timeout=300,
    )
    assert out.returncode == 2 and out.stderr.startswith("error: unknown env 'nope'"), out.stderr[
        -500:
    ]


@pytest.mark.parametrize("where", ["root", "elsewhere"])
def test_a_built_wheel_runs_from_the_checkout_root_and_from_elsewhere(where, tmp_path_factory):
    """`pip wheel .` then the wheel installed without dependencies into a folder put first on
    PYTHONPATH: `python -m hintsjax.run` answers a bad env with its one line, run from the
    checkout's root (whose hintsjax/ shadows the installed one) and from another folder."""
    root = Path(__file__).resolve().parents[1]
    target = wheel_install(tmp_path_factory)
    env = {**os.environ, "PYTHONPATH": str(target)}
    cwd = root if where == "root" else tmp_path_factory.mktemp("elsewhere")
    out = subprocess.run(
        [sys.executable, "-m", "hintsjax.run", "env=nope"],
        cwd=cwd,
        env=env,
        capture_output=True,
        text=True,
        timeout=300,
    )
    assert out.returncode == 2 and out.stderr.startswith("error: unknown env 'nope'"), out.stderr[
        -500:
    ]
    if where == "elsewhere":  # the installed copy, not the checkout's
        probe = subprocess.run(
            [sys.executable, "-c", "import hintsjax.envs as e; print(e.__file__)"],
            cwd=cwd,
            env=env,
            capture_output=True,
            text=True,
            timeout=300,
        )
        assert probe.stdout.strip().startswith(str(target)), probe.stdout + probe.stderr


def test_a_built_wheels_experts_restore_and_hold_only_what_a_restore_reads(tmp_path_factory):
    """The wheel's package data holds every packaged expert, which restores from the installed copy,
    and none of orbax's notes of the machine that wrote it (hintsjax/algorithms/experts.py
    MACHINE_FILES)."""
    target = wheel_install(tmp_path_factory)
    installed = target / "hintsjax" / "experts"
    assert sorted(p.name for p in installed.iterdir() if (p / "expert.json").is_file()) == sorted(
        p.name
        for p in (Path(__file__).resolve().parents[1] / "hintsjax" / "experts").iterdir()
        if (p / "expert.json").is_file()
    )
    assert [p for p in installed.rglob("*") if p.name in ("commit_success.txt", "_sharding")] == []
    entry_points = "".join(
        p.read_text() for p in target.glob("hintsjax-*.dist-info/entry_points.txt")
    )
    assert "[console_scripts]\nhintsjax = hintsjax.console:main" in entry_points
    script = (
        "import hintsjax.algorithms.experts as x, jax; assert x.__file__.startswith(%r), "
        "x.__file__\n"
        "for env in x.packaged(): assert jax.numpy.isfinite(x.load(env).log_std).all(), env\n"
        "print(len(x.packaged()))" % str(target)
    )
    out = subprocess.run(
        [sys.executable, "-c", script],
        cwd=tmp_path_factory.mktemp("elsewhere"),
        env={**os.environ, "PYTHONPATH": str(target)},
        capture_output=True,
        text=True,
        timeout=300,
    )
    assert out.returncode == 0 and out.stdout.strip() == "7", out.stderr[-2000:]


_WHEEL: dict[str, Path] = {}


def wheel_install(tmp_path_factory) -> Path:
    """The project built as a wheel and installed (no dependencies) into a temporary folder,
    once."""
    if "target" not in _WHEEL:
        root = Path(__file__).resolve().parents[1]
        wheels, target = tmp_path_factory.mktemp("wheels"), tmp_path_factory.mktemp("site")
        pip = [sys.executable, "-m", "pip", "-q"]
        subprocess.run(
            [*pip, "wheel", "--no-deps", "-w", str(wheels), str(root)],
            check=True,
            capture_output=True,
            timeout=600,
        )
        subprocess.run(
            [
                *pip,
                "install",
                "--no-deps",
                "--no-compile",
                "--target",
                str(target),
                *map(str, wheels.glob("*.whl")),
            ],
            check=True,
            capture_output=True,
            timeout=600,
        )
        _WHEEL["target"] = target
    return _WHEEL["target"]


SHIPPED_ENVS = (
    "pendulum",
    "acrobot",
    "idp",
    "ant",
    "ant_fast",
    "halfcheetah",
    "humanoid",
    "car_racing",
)


@pytest.mark.parametrize("name", SHIPPED_ENVS)
def test_each_env_carries_its_training_defaults_beside_it(name):
    """An env's defaults live in its module (`TRAINING`, the registry's `training`);
    ENV_DEFAULTS is built from them, with the references' per-agent layers."""
    from hintsjax import envs
    from hintsjax.settings.env_defaults import ENV_DEFAULTS

    training = envs.REGISTRY[name].training
    assert training["hint"] in envs.hint_names(name)
    defaults = ENV_DEFAULTS[name]
    assert defaults["hint"] == training["hint"] and defaults["ppo"] == training["ppo"]
    expert = training["agents"]["expert_ppo"]["ppo"]["total_env_steps"]
    assert defaults["agents"]["expert_ppo"]["ppo"]["total_env_steps"] == expert
    assert set(defaults["agents"]) >= {"expert_ppo", "dagger", "gail"}


def test_an_env_registered_at_run_time_takes_one_call():
    """One registry entry (class, variants, training defaults) is all a new env needs: its
    defaults reach the resolved config without a second write (ENV_DEFAULTS reads the entry)."""
    from hintsjax import envs
    from hintsjax.settings.env_defaults import ENV_DEFAULTS
    from hintsjax.settings.layers import run_config

    entry = envs.REGISTRY["pendulum"]
    envs.REGISTRY["pendulum_copy"] = envs.EnvEntry(
        entry.cls,
        entry.variants,
        training=dict(
            ppo=dict(hidden=(8, 8)),
            learners=dict(ppo=dict(epochs=3)),
            agents=dict(expert_ppo=dict(ppo=dict(total_env_steps=1234))),
        ),
    )
    try:
        cfg = run_config({"env": "pendulum_copy", "agent": "ppo_rgb"})
        assert (cfg.ppo.hidden, cfg.ppo.epochs) == ((8, 8), 3)
        assert (
            run_config({"env": "pendulum_copy", "agent": "expert_ppo"}).ppo.total_env_steps == 1234
        )
    finally:
        dict.pop(envs.REGISTRY, "pendulum_copy")
        dict.pop(ENV_DEFAULTS, "pendulum_copy", None)


def test_a_config_saved_before_the_brax_knobs_resumes_under_their_defaults(tmp_path):
    """Runs saved before ppo.grad_clip, adam_eps, gae_segment, normalize_before_learning,
    critic_trains_encoder, kl_adaptive_lr and reset_every_update existed trained as their defaults
    do, so a config.yaml without them is complete; without clip_eps it is not."""
    cfg = layers.run_config({k: v for k, v in tiny_values().items() if k != "out_dir"})
    layers.save_run_config(tmp_path, cfg)
    values = yaml.safe_load((tmp_path / "config.yaml").read_text())
    for key in (
        "grad_clip",
        "adam_eps",
        "gae_segment",
        "normalize_before_learning",
        "critic_trains_encoder",
        "kl_adaptive_lr",
        "reset_every_update",
    ):
        del values["ppo"][key]
    (tmp_path / "config.yaml").write_text(yaml.safe_dump(values))
    assert layers.load_run_config(tmp_path, complete=True) == cfg
    del values["ppo"]["clip_eps"]
    assert layers.missing_keys(values) == ["ppo.clip_eps"]


def test_a_ctrl_c_while_the_command_still_imports_stops_it_before_anything_is_written(tmp_path):
    """A command's process keeps a Ctrl-C that comes while its modules import (hintsjax/__init__.py
    under `python -m`) and its boundary raises it as the command begins: one line, exit 130, no
    run folder. Python's own handler raised it wherever it landed; inside JAX's garbage-collector
    callback it was dropped and the run trained to its end, exit 0. The signal is sent once the
    package has imported, as `python -m hintsjax.run` does before importing the run module."""
    script = (
        "import os, runpy, signal, sys\n"
        # as `python -m hintsjax.run` starts, its package importing
        "sys.orig_argv = [sys.executable, '-m', 'hintsjax.run']\n"
        "sys.argv = ['-m']\n"
        "import hintsjax\n"
        "os.kill(os.getpid(), signal.SIGINT)\n"  # kept, not raised: the imports go on
        "sys.argv = ['hintsjax.run', 'env=pendulum', 'out_dir=runs', 'name=r']\n"
        "runpy.run_module('hintsjax.run', run_name='__main__', alter_sys=True)\n"
    )
    out = subprocess.run(
        [sys.executable, "-c", script], cwd=tmp_path, capture_output=True, text=True, timeout=300
    )
    assert out.returncode == errors.INTERRUPTED, out.stderr[-2000:]
    assert out.stderr.strip().splitlines() == ["interrupted"]
    assert not (tmp_path / "runs").exists()


@pytest.mark.parametrize(
    "module, kept",
    [("hintsjax.run", True), ("hintsjax.evaluate", True), ("hintsjax.reproduce.sweep", False)],
)
def test_only_a_command_with_the_boundary_keeps_a_stop_while_it_imports(module, kept):
    """Keeping a stop while the modules import is for the commands whose boundary raises it; any
    other process that imports hintsjax (a sweep's worker, a user's `python -m mypkg`) keeps
    Python's own handlers, or SIGTERM would only be kept, never acted on."""
    script = (
        "import signal, sys\n"
        f"sys.orig_argv = [sys.executable, '-m', {module!r}]\n"
        "sys.argv = ['-m']\n"
        "import hintsjax\n"
        "print(signal.getsignal(signal.SIGINT) is signal.default_int_handler,"
        " signal.getsignal(signal.SIGTERM) is signal.SIG_DFL)\n"
    )
    command = [sys.executable, "-c", script]
    out = subprocess.run(command, capture_output=True, text=True, timeout=120)
    assert out.returncode == 0, out.stderr[-2000:]
    assert out.stdout.split() == (["False", "False"] if kept else ["True", "True"])
