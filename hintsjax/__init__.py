"""hintsjax: HINTs (Human-INTuited cues for RL) in JAX. See README.md."""

import os as _os

# Same seed, same result on a GPU too. Without this flag two processes training the same seed on
# an H100 ended with different params (XLA autotunes GPU kernels per compile; measured with
# experiments/determinism.py). It must be set before jax starts; to opt out, put
# --xla_gpu_deterministic_ops=false in XLA_FLAGS yourself.
if "xla_gpu_deterministic_ops" not in _os.environ.get("XLA_FLAGS", ""):
    _os.environ["XLA_FLAGS"] = (_os.environ.get("XLA_FLAGS", "") + " --xla_gpu_deterministic_ops=true").strip()
