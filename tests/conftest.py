"""Settings for the whole test suite.

The traced-program cache (hintsjax/system/program_cache.py) is off: several tests replace a function
at run time (a poisoned trainer, a patched env metric), which no key of that cache can see, and such
a test must never run a program traced for another test. tests/test_program_cache.py turns it on
in folders of its own; tests/test_cli.py and tests/test_group.py for their own runs, which replace
no function inside a traced program (their repeated and resumed runs of one tiny config load what
the first traced; no other test writes or reads an entry). Subprocesses that the tests start
inherit the setting.

Ctrl-C is Python's own handler even where the suite was started in the background (`make test &`
in a script): such a shell starts it with SIGINT ignored, which Python keeps and every process a
test starts inherits, and the tests of the commands' Ctrl-C then saw no signal (one waited 300 s).
So a Ctrl-C at that shell's terminal now stops such a suite too.

HINTSJAX_DEBUG is on: a bug that a test meets raises with its traceback instead of the commands'
one-line report (tests/test_cli.py turns it off to test that report).

Compiling is most of the suite's time on a CPU (the runs it trains are tiny), so:
- **One XLA compilation cache for the whole run**: a folder made once, shared by the xdist workers
  and every process a test starts (they inherit $HINTSJAX_COMPILATION_CACHE), turned on here
  before anything compiles. A program that another test, worker or process compiled already (the
  same resumed run, the command-line runs of one tiny config) is read back, not compiled again.
  XLA keys an entry by the whole program and the flags, so a test that patches a function gets
  its own entry. The folder is removed when the run ends. HINTSJAX_TEST_XLA_CACHE=off turns it off.
- **LLVM's cheapest optimisation level** (`--xla_backend_optimization_level=0`) for the programs the
  default tier compiles, set before JAX's backend starts (subprocesses inherit it; the slow tier
  keeps XLA's default: `pytest_configure`). Their runs are tiny, so
  compiling faster wins over running slower: the whole suite took 851 s on 2 cores with it and
  1120 s without (2026-11-27; docs/tests.md), though test_rank's long probe went from 57 s to 153 s
  (so tests/test_rank.py runs that command in a process of its own, without the flag).
  Results move by float32 rounding only (dagger's vmapped weights 7e-6 from its lone run's).
  Commands run outside the tests keep XLA's default.
- **XLA's loop emitters for CPU fusions** (`--xla_cpu_use_fusion_emitters=false`), for the same
  tier: jaxlib 0.10's newer MLIR fusion emitters took most of a compile; without them the cue
  env's training programs compiled in about half the time (5.0 -> 2.7 s) and `make test` took
  382 s, not 592 s (2026-11-28, 2-core EPYC; docs/tests.md). Also float32 rounding only: one
  test's two programs that were bit for bit equal are now 1.5e-8 apart (test_learning's target_kl).
"""

import os
import shutil
import signal
import subprocess
import tempfile

import pytest
import xla_tier  # tests/xla_tier.py

from hintsjax.system import compilation_cache, errors, program_cache

if signal.getsignal(signal.SIGINT) is signal.SIG_IGN:
    signal.signal(signal.SIGINT, signal.default_int_handler)  # reset to default on exec
os.environ[program_cache.ENV_VAR] = "off"
os.environ[errors.DEBUG] = "1"

# the folder this run made (set by the first process: xdist's controller)
MADE_CACHE = "HINTSJAX_TEST_XLA_CACHE_MADE"
if os.environ.get("HINTSJAX_TEST_XLA_CACHE", "on") != "off":
    if MADE_CACHE not in os.environ:
        os.environ[MADE_CACHE] = tempfile.mkdtemp(prefix="hintsjax-tests-xla-")
        os.environ[compilation_cache.ENV_VAR] = os.environ[MADE_CACHE]
    compilation_cache.enable(os.environ[MADE_CACHE], min_compile_seconds=0)


def pytest_configure(config):
    """LLVM -O0 and the loop emitters for the default tier, set before JAX's backend starts (it
    reads XLA_FLAGS once; no test module is imported yet, and xdist's workers start later and
    inherit it). The slow tier alone (`-m slow`, `make test-slow`) keeps XLA's default: its drives
    run for minutes, which -O0 made several times longer (the humanoid's 2x10^5-step drive took
    1296 s on a core)."""
    if config.option.markexpr.strip() != "slow" and xla_tier.OPTIMIZATION not in os.environ.get(
        "XLA_FLAGS", ""
    ):
        os.environ["XLA_FLAGS"] = xla_tier.default_tier_flags()


def pytest_unconfigure(config):
    """The process that made the cache folder (xdist's controller, or pytest alone) removes it."""
    if not hasattr(config, "workerinput") and os.environ.get(MADE_CACHE):
        shutil.rmtree(os.environ.pop(MADE_CACHE), ignore_errors=True)


@pytest.fixture(scope="module")
def traced_programs_kept():
    """The traced-program cache on for a module's runs, in-process and in the processes they start
    (`pytestmark = pytest.mark.usefixtures("traced_programs_kept")`): for files that replace no
    function inside a traced program (tests/test_cli.py, tests/test_group.py), whose repeated and
    resumed runs of one tiny config then load what the first traced instead of tracing it again. The
    cache's key digests the source of every loaded module."""
    with pytest.MonkeyPatch.context() as patch:
        patch.setenv(program_cache.ENV_VAR, "on")
        yield


@pytest.fixture
def unwritable():
    """A function that makes a folder take no new file, undone after the test: chattr +i as root
    (root ignores permissions), else mode 555; the test skips where neither holds."""
    made = []

    def refuse(folder) -> None:
        if os.geteuid() == 0:
            if shutil.which("chattr") is None:
                pytest.skip("root without chattr: no way to make a folder refuse root's writes")
            out = subprocess.run(["chattr", "+i", str(folder)], capture_output=True, text=True)
            if out.returncode != 0:
                pytest.skip(f"this file system has no immutable flag: {out.stderr.strip()}")
        else:
            os.chmod(folder, 0o555)
        made.append(folder)

    yield refuse
    for folder in made:
        if os.geteuid() == 0:
            subprocess.run(["chattr", "-i", str(folder)], capture_output=True)
        else:
            os.chmod(folder, 0o755)
