"""Settings for the whole test suite.

The traced-program cache (hintsjax/system/program_cache.py) is off: several tests replace a function at
run time (a poisoned trainer, a patched env metric), which no key of that cache can see, and a
test must never run a program traced for another test. tests/test_program_cache.py turns it on
in folders of its own. Subprocesses that the tests start inherit the setting.

HINTSJAX_DEBUG is on: a bug that a test meets raises with its traceback instead of the commands'
one-line report (tests/test_cli.py turns it off to test that report).
"""

import os

from hintsjax.system import errors, program_cache

os.environ[program_cache.ENV_VAR] = "off"
os.environ[errors.DEBUG] = "1"
