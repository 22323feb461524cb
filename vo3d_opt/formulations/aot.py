"""The decision kernels compiled ahead of time, so that a first ``select()`` does not wait for
numba's JIT (issue 9 §5: 27–50 s with an empty cache on the 2-core test machines).

``build()`` compiles ``kernel.decide`` (``select``), ``swarm.decide_range`` (``select_many``'s
loop over the vehicles), ``swarm.neighbor_lists`` and ``swarm.nearest_lists`` (its neighbour
lists, from every pair within range or from each vehicle's nearest) with numba's
ahead-of-time compiler (``numba.pycc``) into one extension module next to this file
(``vo3d compile``; ``make`` runs it), with a stamp of what it was built from: the package's
sources, the Python, numpy and numba versions and the CPU (built for this machine's CPU, as
numba's JIT would). ``load()`` returns the compiled entries only when the stamp matches the
code this process imported and this machine, and numba is not asked to debug
(``NUMBA_DISABLE_JIT``, ``NUMBA_BOUNDSCHECK``); otherwise the selector uses the JIT kernels, so
an edited source or a moved environment never runs a stale or foreign kernel. It is the same
code: everything below the four entries is compiled by the same dispatchers (their
flags, ``error_model="numpy"``) and linked into the module, and the answers are bitwise those
of the JIT kernels (tests/test_aot.py). The module's wrappers release the GIL, as the JIT's
``nogil`` ones do, so ``vo3d_opt.swarm.decide_all`` runs ``decide_range`` on several threads as
before (a flag set in the compiling process only). With the neighbour lists (the counting
sort of the k-d tree's pairs, the ranking of its nearest) in the module too, a first
``select_many`` compiles nothing either.

Each entry is loaded behind a check of its arguments' types (``_checked``: the module trusts
them); ``select`` calls ``decide`` without it, as it builds every array itself
(``selector._decide_unchecked``).

``numba.pycc`` has been "pending deprecation" since numba 0.57 with no replacement yet; when it
goes, ``build()`` fails with its error and everything runs on the JIT kernels as before.
"""

from __future__ import annotations

import hashlib
import importlib.machinery
import importlib.util
import json
import os
import platform
import subprocess
import sys
import sysconfig
import tempfile
import time
import warnings
from collections.abc import Callable
from pathlib import Path
from typing import Any, NamedTuple, cast

import numpy as np

from . import kernel, swarm
from .swarm import SWARM_FIELDS, Swarm

#: The extension module's name (its file: NAME + the interpreter's extension suffix).
NAME = "_kernel_aot"
HERE = Path(__file__).resolve().parent
PACKAGE = HERE.parent
#: ``kernel.decide``'s arguments (p, v_now, v_pref, nbrs, prisms, limits, options, plane_tab,
#: gen_tab, out): the dimensions of its float64 C arrays.
DECIDE_NDIMS = (1, 1, 1, 2, 2, 1, 1, 2, 2, 1)
#: ``swarm.decide_range``'s arrays after (sw, lo, hi): options, plane_tab, gen_tab, out.
RANGE_NDIMS = (1, 2, 2, 2)
#: ``swarm.neighbor_lists``' arguments (a, b, dist, sensing_range, place, k, span): (dtype,
#: dimensions) of each C array, None for the float and the int between them.
LISTS_KINDS = (
    (np.int64, 1),
    (np.int64, 1),
    (np.float64, 1),
    None,
    (np.int64, 1),
    None,
    (np.int64, 2),
)
#: ``swarm.nearest_lists``' arguments (P, who, near, far, sensing_range, chosen), as above.
NEAREST_KINDS = (
    (np.float64, 2),
    (np.int64, 1),
    (np.int64, 2),
    (np.float64, 2),
    None,
    (np.int64, 2),
)

Kernel = Callable[..., Any]


class Kernels(NamedTuple):
    """The compiled entries, each behind a check of its arguments (``_checked``)."""

    decide: Kernel  # kernel.decide
    decide_range: Kernel  # formulations.swarm.decide_range
    neighbor_lists: Kernel  # formulations.swarm.neighbor_lists (returns the lists)
    nearest_lists: Kernel  # formulations.swarm.nearest_lists (returns the settled flags)


def module_path(directory: Path = HERE) -> Path:
    return directory / (NAME + (sysconfig.get_config_var("EXT_SUFFIX") or ".so"))


def stamp_path(directory: Path = HERE) -> Path:
    return directory / (NAME + ".json")


def _source_hash() -> str:
    """A hash of the package's Python files as they are on disk now (editors' lock and backup
    files, which start with a dot, and anything that is not a regular file left out)."""
    digest = hashlib.sha256()
    for path in sorted(PACKAGE.rglob("*.py")):
        if path.name.startswith(".") or not path.is_file():
            continue
        digest.update(path.relative_to(PACKAGE).as_posix().encode() + b"\0")
        digest.update(path.read_bytes() + b"\0")
    return digest.hexdigest()


#: The sources this process imported (the package imports this module at its own import): a
#: module built from files edited since is refused, even if it is on disk now.
SOURCES_AT_IMPORT = _source_hash()


def stamp(sources: str | None = None) -> dict[str, str]:
    """What a compiled module must have been built from to be used: the package's sources
    (``sources``, else as they are on disk now), the versions that compiled it and the CPU it
    was compiled for."""
    import llvmlite.binding as llvm
    import numba

    return {
        "sources": _source_hash() if sources is None else sources,
        "python": sys.version,
        "numpy": np.__version__,
        "numba": numba.__version__,
        "machine": platform.machine(),
        "cpu": llvm.get_host_cpu_name(),
        "cpu_features": llvm.get_host_cpu_features().flatten(),
    }


def _export(directory: str) -> None:
    """Compile the module into ``directory`` (in a process of its own: see ``build``)."""
    import numba
    import numba.pycc.compiler as pycc_compiler
    from numba import types
    from numba.pycc import CC

    decide, decide_range = kernel.decide, swarm.decide_range
    neighbor_lists, nearest_lists = swarm.neighbor_lists, swarm.nearest_lists

    compile_extra = pycc_compiler.compile_extra

    def compile_nogil(*args: Any, **kwargs: Any) -> Any:
        flags = [a for a in (*args, *kwargs.values()) if isinstance(a, pycc_compiler.Flags)]
        if len(flags) != 1:  # numba changed how pycc compiles: fail rather than hold the GIL
            raise RuntimeError("numba.pycc's compile_extra no longer takes one Flags")
        # as the JIT kernels' nogil, for select_many's threads (an Option numba's stubs omit)
        setattr(flags[0], "release_gil", True)  # noqa: B010
        return compile_extra(*args, **kwargs)

    pycc_compiler.compile_extra = compile_nogil  # this process only compiles the module

    def decide_aot(p, v_now, v_pref, nbrs, prisms, limits, options, plane_tab, gen_tab, out):  # noqa: ANN001
        # only a call: decide and everything below it compile with their own flags
        decide(p, v_now, v_pref, nbrs, prisms, limits, options, plane_tab, gen_tab, out)

    def decide_range_aot(sw, lo, hi, options, plane_tab, gen_tab, out):  # noqa: ANN001
        decide_range(sw, lo, hi, options, plane_tab, gen_tab, out)

    def neighbor_lists_aot(a, b, dist, sensing_range, place, k, span):  # noqa: ANN001
        return neighbor_lists(a, b, dist, sensing_range, place, k, span)

    def nearest_lists_aot(P, who, near, far, sensing_range, chosen):  # noqa: ANN001
        return nearest_lists(P, who, near, far, sensing_range, chosen)

    def array(dtype: type, ndim: int) -> types.Array:
        return types.Array(numba.from_dtype(np.dtype(dtype)), ndim, "C")

    f8 = [array(np.float64, nd) for nd in RANGE_NDIMS]
    swarm_type = types.NamedTuple([array(dt, nd) for dt, nd in SWARM_FIELDS], Swarm)
    cc = CC(NAME)
    cc.output_dir = directory
    cc.target_cpu = "host"  # as the JIT compiles; the stamp names the CPU
    cc.verbose = False
    cc.export("decide", types.void(*[array(np.float64, nd) for nd in DECIDE_NDIMS]))(decide_aot)
    cc.export("decide_range", types.void(swarm_type, types.int64, types.int64, *f8))(
        decide_range_aot
    )
    scalars = iter((types.float64, types.int64))
    lists_args = [next(scalars) if kind is None else array(*kind) for kind in LISTS_KINDS]
    cc.export("neighbor_lists", array(np.int64, 1)(*lists_args))(neighbor_lists_aot)
    nearest_args = [types.float64 if kind is None else array(*kind) for kind in NEAREST_KINDS]
    cc.export("nearest_lists", array(np.bool_, 1)(*nearest_args))(nearest_lists_aot)
    with warnings.catch_warnings():  # pycc's pending-deprecation notice: said in the docstring
        warnings.simplefilter("ignore")
        cc.compile()


def build(directory: Path = HERE) -> tuple[Path, float]:
    """Compile the module and its stamp into ``directory``: (the module's path, seconds).
    Runs in a child process with an empty numba cache of its own and no other ``NUMBA_*``
    setting, so that every function is compiled from its source as the JIT would, never
    loaded from a cache built for other code. The module and then its stamp replace the old
    ones atomically (built in a scratch folder inside ``directory``, so a folder that cannot
    be written fails at once). Raises RuntimeError when the compiler fails or the sources
    change during the build, OSError when ``directory`` cannot be written."""
    directory = Path(directory)
    directory.mkdir(parents=True, exist_ok=True)
    t0, before = time.perf_counter(), stamp()
    with tempfile.TemporaryDirectory(prefix=".aot-build-", dir=directory) as tmp:
        env = {k: v for k, v in os.environ.items() if not k.startswith("NUMBA_")}
        env["NUMBA_CACHE_DIR"] = str(Path(tmp) / "numba-cache")
        code = f"from vo3d_opt.formulations.aot import _export; _export({tmp!r})"
        child = subprocess.run(
            [sys.executable, "-c", code], env=env, capture_output=True, text=True, check=False
        )
        built = module_path(Path(tmp))
        if child.returncode != 0 or not built.exists():
            tail = " | ".join((child.stderr or child.stdout).strip().splitlines()[-3:])
            raise RuntimeError(f"numba.pycc could not compile the kernel: {tail}")
        if stamp() != before:
            raise RuntimeError("the sources changed during the build: run it again")
        stamp_path(directory).unlink(missing_ok=True)  # no stamp until the new module is in
        os.replace(built, module_path(directory))
        written = Path(tmp) / stamp_path(directory).name
        written.write_text(json.dumps(before, indent=1) + "\n")
        os.replace(written, stamp_path(directory))
    return module_path(directory), time.perf_counter() - t0


def load(directory: Path = HERE) -> tuple[Kernels | None, str]:
    """The compiled entries when a module built from the code this process imported, for this
    machine, is in ``directory``, else None; and a sentence saying which. ``VO3D_AOT=0`` turns
    it off (the JIT kernels, e.g. to time them), and so do numba's debugging switches. Never
    raises: anything amiss means the JIT kernels. (A module is loaded once per path and
    process: one rebuilt in place after that is used by the next process.)"""
    import numba

    if os.environ.get("VO3D_AOT", "").strip() == "0":
        return None, "the ahead-of-time kernel is turned off (VO3D_AOT=0)"
    if getattr(numba.config, "DISABLE_JIT", 0) or getattr(numba.config, "BOUNDSCHECK", 0):
        return None, "numba is set to debug (NUMBA_DISABLE_JIT or NUMBA_BOUNDSCHECK)"
    path, stamp_file = module_path(directory), stamp_path(directory)
    if not path.exists() or not stamp_file.exists():
        return None, "no ahead-of-time kernel (`vo3d compile` builds one)"
    try:
        built = json.loads(stamp_file.read_text())
    except (OSError, ValueError):
        return None, f"{stamp_file} is unreadable"
    now = stamp(SOURCES_AT_IMPORT)
    changed = sorted(k for k in now if not isinstance(built, dict) or built.get(k) != now[k])
    if changed:
        return None, f"the ahead-of-time kernel is stale ({', '.join(changed)} changed)"
    try:
        loader = importlib.machinery.ExtensionFileLoader(NAME, str(path))
        spec = importlib.util.spec_from_loader(NAME, loader)
        assert spec is not None  # a loader is given
        module = importlib.util.module_from_spec(spec)
        loader.exec_module(module)
        entries = module.decide, module.decide_range, module.neighbor_lists, module.nearest_lists
    except (ImportError, OSError, AttributeError) as exc:
        return None, f"{path} does not load ({type(exc).__name__}: {exc})"
    kernels = Kernels(
        _checked(entries[0], kernel.decide, _decide_args_ok),
        _checked(entries[1], swarm.decide_range, _range_args_ok),
        _checked(entries[2], swarm.neighbor_lists, _lists_args_ok),
        _checked(entries[3], swarm.nearest_lists, _nearest_args_ok),
    )
    return kernels, f"ahead-of-time kernel {path} (built from this code for this machine)"


Kinds = tuple[tuple[np.dtype, int], ...]


def _arrays_ok(arrays: tuple[object, ...], kinds: Kinds) -> bool:
    """Each of ``arrays`` an ndarray (not a subclass) of its (dtype, dimensions), C-contiguous
    and aligned."""
    if len(arrays) != len(kinds):
        return False
    for a, (dtype, ndim) in zip(arrays, kinds, strict=True):
        if type(a) is not np.ndarray or a.dtype != dtype or a.ndim != ndim:
            return False
        flags = a.flags
        if not (flags.c_contiguous and flags.aligned):
            return False
    return True


def _kinds(fields: tuple[tuple[type, int], ...]) -> Kinds:
    return tuple((np.dtype(dtype), ndim) for dtype, ndim in fields)


_DECIDE_KINDS = _kinds(tuple((np.float64, nd) for nd in DECIDE_NDIMS))
_RANGE_KINDS = _kinds(tuple((np.float64, nd) for nd in RANGE_NDIMS))
_SWARM_KINDS = _kinds(SWARM_FIELDS)


def _decide_args_ok(args: tuple[object, ...]) -> bool:
    return _arrays_ok(args, _DECIDE_KINDS) and args[-1].flags.writeable  # type: ignore[attr-defined]


def _range_args_ok(args: tuple[object, ...]) -> bool:
    if len(args) != 3 + len(RANGE_NDIMS) or type(args[0]) is not Swarm:
        return False
    ints = all(isinstance(i, int | np.integer) and not isinstance(i, bool) for i in args[1:3])
    return (
        ints
        and _arrays_ok(tuple(args[0]), _SWARM_KINDS)
        and _arrays_ok(args[3:], _RANGE_KINDS)
        and args[-1].flags.writeable  # type: ignore[attr-defined]
    )


_LISTS_ARRAYS = tuple(i for i, kind in enumerate(LISTS_KINDS) if kind is not None)
_LISTS_KINDS = _kinds(tuple(kind for kind in LISTS_KINDS if kind is not None))


def _lists_args_ok(args: tuple[object, ...]) -> bool:
    """``neighbor_lists``' arguments: its arrays as compiled, a float range and an int k."""
    if len(args) != len(LISTS_KINDS):
        return False
    k = args[5]
    return (
        isinstance(args[3], float)
        and isinstance(k, int)
        and not isinstance(k, bool)
        and _arrays_ok(tuple(args[i] for i in _LISTS_ARRAYS), _LISTS_KINDS)
        and args[-1].flags.writeable  # type: ignore[attr-defined]
    )


_NEAREST_ARRAYS = tuple(i for i, kind in enumerate(NEAREST_KINDS) if kind is not None)
_NEAREST_KINDS = _kinds(tuple(kind for kind in NEAREST_KINDS if kind is not None))


def _nearest_args_ok(args: tuple[object, ...]) -> bool:
    """``nearest_lists``' arguments: its arrays as compiled, a float range, and shapes that
    agree (the module reads near and far by who's length and writes chosen's rows). The
    values are trusted, as ``neighbor_lists``' are: ``vehicle_links`` builds them (who from
    ``np.flatnonzero``, near from the tree)."""
    if len(args) != len(NEAREST_KINDS) or not isinstance(args[4], float):
        return False
    arrays = tuple(args[i] for i in _NEAREST_ARRAYS)
    if not _arrays_ok(arrays, _NEAREST_KINDS):
        return False
    P, who, near, far, chosen = cast(tuple[np.ndarray, ...], arrays)
    D = who.shape[0]
    return (
        P.shape[1] == 3
        and near.shape == far.shape
        and near.shape[0] == D
        and chosen.shape[0] == D
        and 1 <= chosen.shape[1] <= near.shape[1]
        and bool(chosen.flags.writeable)
    )


def _checked(compiled: Kernel, jit: Kernel, ok: Callable[[tuple[object, ...]], bool]) -> Kernel:
    """``compiled`` behind a check of its arguments: a compiled module trusts the types it was
    compiled for (an int64 array read as float64, a 2D array as 1D, a strided view as
    contiguous: wrong answers or memory read out of bounds), so anything else goes to the JIT
    kernel ``jit``, which dispatches on the types (and raises where it must)."""

    def call(*args: object) -> Any:
        return (compiled if ok(args) else jit)(*args)

    call.compiled = compiled  # type: ignore[attr-defined]  # the unchecked call (select, timing)
    return call
