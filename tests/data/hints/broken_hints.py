"""A hint file that fails to import (tests/data/bad_inputs.yaml)."""

from hintsjax.envs import no_such_name  # noqa: F401
