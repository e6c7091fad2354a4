"""Traced programs kept on disk, so that a second run of the same command skips Python tracing.

JAX's persistent compilation cache (`compilation_cache.py`) saves XLA's compile, but every run
still traces its programs in Python first: for the ant's training and evaluation programs that
was most of a warm start (run_path.json `trace_split`). This module keeps each traced program as
a `jax.export` artifact (its StableHLO) in a `traced/` folder inside the compilation cache's
folder, and a later process that asks for the same program loads it instead of tracing it; XLA's
compile of the loaded program then hits the persistent cache. Cold runs compile the same
program through the same path, so both compute the same numbers (tests/test_program_cache.py).

More of what it owns and why: docs/design.md, "Module notes", hintsjax/system/program_cache.py.
"""

from __future__ import annotations

import hashlib
import importlib.metadata
import inspect
import os
import pickle
import sys
import sysconfig
import warnings
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Callable

import jax
import numpy as np
from jax import export
from jax.api_util import shaped_abstractify

from hintsjax import envs
from hintsjax.envs import hints

# "off" turns the traced-program cache off (the compile cache stays)
ENV_VAR = "HINTSJAX_TRACE_CACHE"
FOLDER = "traced"
LIBRARIES = (
    "jax",
    "jaxlib",
    "flax",
    "optax",
    "chex",
    "numpy",
    "mujoco",
    "mujoco-mjx",
    "orbax-checkpoint",
    "brax",
    "playground",
)
NUMERIC_SETTINGS = (
    "jax_enable_x64",
    "jax_default_matmul_precision",
    "jax_default_prng_impl",
    "jax_threefry_partitionable",
)
_OFF = ("off", "0", "false", "no", "none")
PACKAGE = Path(__file__).resolve().parents[1]  # the hintsjax folder, wherever it is installed


def folder() -> Path | None:
    """Where traced programs are kept: `traced/` inside the persistent compilation cache's folder
    while that cache is on (compilation_cache.enable), unless $HINTSJAX_TRACE_CACHE is off."""
    base = jax.config.jax_compilation_cache_dir
    if not base or os.environ.get(ENV_VAR, "").strip().lower() in _OFF:
        return None
    return Path(base) / FOLDER


def _library_roots() -> tuple[str, ...]:
    """The installed libraries' folders, as sysconfig names them and with links resolved."""
    paths = sysconfig.get_paths()
    named = [paths[k] for k in ("stdlib", "platstdlib", "purelib", "platlib") if k in paths]
    return tuple({*named, *(str(Path(p).resolve()) for p in named)})


def _source_file(obj: Any) -> Path | None:
    """The file that defines a registered function or class (None: none, e.g. a notebook's)."""
    try:
        source = inspect.getsourcefile(inspect.unwrap(getattr(obj, "func", obj)))
    except TypeError:
        return None
    return Path(source) if source and Path(source).is_file() else None


def sources_digest() -> str | None:
    """A digest of the package's source and data files (wherever it is installed) and of every
    loaded module outside the installed libraries (a script's or a test's own envs and hints);
    None when a registered env or hint has no source file, so that nothing can key its program."""
    registered = [entry.cls for entry in envs.REGISTRY.values()]
    registered += [spec.fn for table in hints._HINTS.values() for spec in table.values()]
    if any(_source_file(obj) is None for obj in registered):
        return None
    files = set()
    for package in (PACKAGE, Path(envs.__file__).parent):
        files.update(p.resolve() for p in package.rglob("*.py"))
        files.update(p.resolve() for p in package.glob("assets/*"))
    roots = _library_roots()
    for module in list(sys.modules.values()):
        path = getattr(module, "__file__", None)
        # most modules are the libraries', recognised by their path as it stands; only the rest
        # are resolved (links) before the same test
        if (
            path
            and path.endswith(".py")
            and not path.startswith(roots)
            and not str(Path(path).resolve()).startswith(roots)
        ):
            files.add(Path(path).resolve())
    digest = hashlib.sha256()
    for path in sorted(files):
        try:
            digest.update(f"{path.name}:{hashlib.sha256(path.read_bytes()).hexdigest()}\n".encode())
        except OSError:
            return None
    return digest.hexdigest()


def _versions() -> str:
    found = []
    for name in LIBRARIES:
        try:
            found.append(f"{name}={importlib.metadata.version(name)}")
        except importlib.metadata.PackageNotFoundError:
            found.append(f"{name}=-")
    return ",".join(found)


def _spec(x: Any) -> jax.ShapeDtypeStruct:
    """An argument's shape and dtype, weak (a Python number's) or not, as `jax.jit` sees it."""
    if not hasattr(x, "dtype"):  # a Python number
        x = shaped_abstractify(x)
    return jax.ShapeDtypeStruct(x.shape, x.dtype, weak_type=bool(getattr(x, "weak_type", False)))


def _shape_of(x: Any) -> jax.ShapeDtypeStruct:
    """A traced program's argument or result: its shape and dtype (a stored program keeps no weak
    types)."""
    return jax.ShapeDtypeStruct(x.shape, x.dtype)


def program_key(name: str, context: str, leaves: list[Any], tree: Any) -> str | None:
    """The key of program `name` described by `context` for arguments (leaves, tree); None when
    the sources cannot be digested."""
    sources = sources_digest()
    if sources is None:
        return None
    device = jax.devices()[0]
    settings = ",".join(f"{s}={getattr(jax.config, s, None)}" for s in NUMERIC_SETTINGS)
    parts = [
        name,
        context,
        str(tree),
        repr([(s.shape, str(s.dtype), s.weak_type) for s in map(_spec, leaves)]),
        sources,
        _versions(),
        sys.version,
        device.platform,
        getattr(device, "device_kind", ""),
        str(len(jax.devices())),
        os.environ.get("XLA_FLAGS", ""),
        settings,
    ]
    return hashlib.sha256("\n".join(parts).encode()).hexdigest()[:32]


@dataclass(frozen=True)
class Program:
    """A compiled program that takes and returns the original pytrees (as a jax executable
    does), compiled from a traced program (`Traced.compile`)."""

    compiled: Any  # jax.stages.Compiled of the exported program's call, on flat arguments
    in_tree: Any
    out_tree: Any

    def __call__(self, *args: Any) -> Any:
        leaves, tree = jax.tree.flatten(args)
        if tree != self.in_tree:
            raise TypeError(
                "arguments of another structure than the program was traced for: "
                f"{tree} != {self.in_tree}"
            )
        leaves = [
            x if isinstance(x, jax.Array) else np.asarray(x, a.dtype)
            for x, a in zip(leaves, self.compiled.in_avals[0])
        ]
        return jax.tree.unflatten(self.out_tree, self.compiled(*leaves))

    @property
    def input_shardings(self) -> tuple[tuple[Any, ...], dict]:
        """As a jax executable's: (per positional argument, its shardings' tree; {})."""
        return jax.tree.unflatten(self.in_tree, list(self.compiled.input_shardings[0])), {}

    def memory_analysis(self) -> Any:
        return self.compiled.memory_analysis()


@dataclass(frozen=True)
class Traced:
    """A traced program, from the cache or traced now: what `jax.jit(f).lower(...)` gives, as far
    as this package uses it (`out_info`, `compile`)."""

    exported: Any  # jax.export.Exported of the function on flat arguments
    in_tree: Any
    out_tree: Any
    loaded: bool  # read from the cache (not traced by this process)

    @property
    def out_info(self) -> Any:
        return jax.tree.unflatten(self.out_tree, [_shape_of(a) for a in self.exported.out_avals])

    def compile(self, compiler_options: dict[str, Any] | None = None) -> Program:
        specs = [_shape_of(a) for a in self.exported.in_avals]
        lowered = jax.jit(self.exported.call).lower(*specs)
        return Program(lowered.compile(compiler_options), self.in_tree, self.out_tree)


def trace(fn: Callable[..., Any], leaves: list[Any], in_tree: Any) -> Traced:
    """Trace `fn` (a function of the pytrees `in_tree` holds) for arguments shaped like `leaves`."""
    out_tree = []

    def flat(*args):
        out_leaves, tree = jax.tree.flatten(fn(*jax.tree.unflatten(in_tree, args)))
        out_tree.append(tree)
        return out_leaves

    exported = export.export(jax.jit(flat))(*[_spec(x) for x in leaves])
    return Traced(exported, in_tree, out_tree[0], loaded=False)


def _load(path: Path) -> Traced | None:
    try:
        with path.open("rb") as f:
            blob, in_tree, out_tree = pickle.load(f)
        return Traced(export.deserialize(bytearray(blob)), in_tree, out_tree, loaded=True)
    except Exception as e:  # noqa: BLE001  an unreadable entry of any kind is traced afresh
        print(
            f"warning: traced program {path.name} unreadable ({type(e).__name__}); "
            "tracing it again",
            file=sys.stderr,
        )
        return None


def _store(path: Path, traced: Traced) -> None:
    try:
        blob = bytes(traced.exported.serialize())
        path.parent.mkdir(parents=True, exist_ok=True)
        partial_path = path.with_name(f".{path.name}.{os.getpid()}")
        with partial_path.open("wb") as f:
            pickle.dump((blob, traced.in_tree, traced.out_tree), f)
        partial_path.replace(path)  # atomic: a reader sees a whole entry or none
    except Exception as e:  # noqa: BLE001  a program that cannot be kept is still run
        warnings.warn(f"traced program not kept ({type(e).__name__}: {e})", stacklevel=3)


def lower(fn: Callable[..., Any], *args: Any, name: str, context: str | None) -> Any:
    """`jax.jit(fn).lower(*args)`, or, where the cache is on and `context` (a description of
    everything `fn` depends on besides its code and its arguments' shapes; None: it cannot be
    described) allows, the same program loaded from the cache or traced and kept there. Either
    result has `out_info` and `compile(compiler_options=None)`, and the compiled program takes and
    returns the same pytrees."""
    leaves, in_tree = jax.tree.flatten(args)
    where = folder()
    single = all(len(getattr(getattr(x, "sharding", None), "device_set", ())) <= 1 for x in leaves)
    key = (
        program_key(name, context, leaves, in_tree)
        if where is not None and context is not None and single
        else None
    )
    if key is None:
        return jax.jit(fn).lower(*args)
    path = where / f"{name}-{key}.bin"
    if path.exists():
        traced = _load(path)
        if traced is not None and traced.in_tree == in_tree:
            return traced
    traced = trace(fn, leaves, in_tree)
    _store(path, traced)
    return traced
