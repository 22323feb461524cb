"""The decision kernels compiled ahead of time, so that a first ``select()`` or ``select_many()``
does not wait for numba's JIT (issue 9 §5: 27–50 s with an empty cache on the 2-core test
machines).

``build()`` compiles ``kernel.decide`` (``select``) and ``swarm.decide_range`` (``select_many``)
with numba's ahead-of-time compiler (``numba.pycc``) into one extension module next to this
file (``vo3d compile``; ``make install`` runs it), with a stamp of what it was built from: the
package's sources, the Python, numpy and numba versions and the CPU (built for this machine's
CPU, as numba's JIT would). ``load()`` returns the compiled entries only when the stamp matches
the running code and machine; otherwise the selector uses the JIT kernels, so an edited source
or a moved environment never runs a stale or foreign kernel. It is the same code: everything
below the two entries is compiled by the same dispatchers (their flags, ``error_model="numpy"``)
and linked into the module, and the answers are bitwise those of the JIT kernels
(tests/test_aot.py). The module's wrappers release the GIL, as the JIT's ``nogil`` ones do, so
``vo3d_opt.swarm.decide_all`` runs ``decide_range`` on several threads as before (a flag set in
the compiling process only).

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
from typing import Any, NamedTuple

import numpy as np

#: The extension module's name (its file: NAME + the interpreter's extension suffix).
NAME = "_kernel_aot"
HERE = Path(__file__).resolve().parent
PACKAGE = HERE.parent
#: ``kernel.decide``'s arguments (p, v_now, v_pref, nbrs, prisms, limits, options, plane_tab,
#: gen_tab, out): the dimensions of its float64 C arrays.
DECIDE_NDIMS = (1, 1, 1, 2, 2, 1, 1, 2, 2, 1)
#: ``swarm.decide_range``'s arrays after (sw, lo, hi): options, plane_tab, gen_tab, out.
RANGE_NDIMS = (1, 2, 2, 2)

Kernel = Callable[..., None]


class Kernels(NamedTuple):
    """The compiled entries, each behind a check of its arguments (``_checked``)."""

    decide: Kernel  # kernel.decide
    decide_range: Kernel  # formulations.swarm.decide_range


def module_path(directory: Path = HERE) -> Path:
    return directory / (NAME + (sysconfig.get_config_var("EXT_SUFFIX") or ".so"))


def stamp_path(directory: Path = HERE) -> Path:
    return directory / (NAME + ".json")


def stamp() -> dict[str, str]:
    """What a compiled module must have been built from to be used: the package's sources,
    the versions that compiled it and the CPU it was compiled for."""
    import llvmlite.binding as llvm
    import numba

    digest = hashlib.sha256()
    for path in sorted(PACKAGE.rglob("*.py")):
        digest.update(path.relative_to(PACKAGE).as_posix().encode() + b"\0")
        digest.update(path.read_bytes() + b"\0")
    return {
        "sources": digest.hexdigest(),
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

    from .kernel import decide
    from .swarm import SWARM_FIELDS, Swarm, decide_range

    compile_extra = pycc_compiler.compile_extra

    def compile_nogil(*args: Any, **kwargs: Any) -> Any:
        args[5].release_gil = True  # the flags: as the JIT kernels' nogil, for select_many
        return compile_extra(*args, **kwargs)

    pycc_compiler.compile_extra = compile_nogil  # this process only compiles the module

    def decide_aot(p, v_now, v_pref, nbrs, prisms, limits, options, plane_tab, gen_tab, out):  # noqa: ANN001
        # only a call: decide and everything below it compile with their own flags
        decide(p, v_now, v_pref, nbrs, prisms, limits, options, plane_tab, gen_tab, out)

    def decide_range_aot(sw, lo, hi, options, plane_tab, gen_tab, out):  # noqa: ANN001
        decide_range(sw, lo, hi, options, plane_tab, gen_tab, out)

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
    with warnings.catch_warnings():  # pycc's pending-deprecation notice: said in the docstring
        warnings.simplefilter("ignore")
        cc.compile()


def build(directory: Path = HERE) -> tuple[Path, float]:
    """Compile the module and its stamp into ``directory``: (the module's path, seconds).
    Runs in a child process with an empty numba cache of its own, so that every function is
    compiled from its source, never loaded from a cache built for other code. Raises
    RuntimeError (with the child's last lines) when the compiler fails."""
    directory = Path(directory)
    directory.mkdir(parents=True, exist_ok=True)
    t0 = time.perf_counter()
    with tempfile.TemporaryDirectory(prefix="vo3d-aot-") as tmp:
        env = {**os.environ, "NUMBA_CACHE_DIR": str(Path(tmp) / "numba-cache")}
        code = f"from vo3d_opt.formulations.aot import _export; _export({tmp!r})"
        child = subprocess.run(
            [sys.executable, "-c", code], env=env, capture_output=True, text=True, check=False
        )
        built = module_path(Path(tmp))
        if child.returncode != 0 or not built.exists():
            tail = " | ".join((child.stderr or child.stdout).strip().splitlines()[-3:])
            raise RuntimeError(f"numba.pycc could not compile the kernel: {tail}")
        stamp_path(directory).unlink(missing_ok=True)  # no stamp until the new module is in
        os.replace(built, module_path(directory))
    stamp_path(directory).write_text(json.dumps(stamp(), indent=1) + "\n")
    return module_path(directory), time.perf_counter() - t0


def load(directory: Path = HERE) -> tuple[Kernels | None, str]:
    """The compiled entries when a module built from this code for this machine is in
    ``directory``, else None; and a sentence saying which. The environment variable
    ``VO3D_AOT=0`` turns it off (the JIT kernels, e.g. to time them)."""
    if os.environ.get("VO3D_AOT", "").strip() == "0":
        return None, "the ahead-of-time kernel is turned off (VO3D_AOT=0)"
    path, stamp_file = module_path(directory), stamp_path(directory)
    if not path.exists() or not stamp_file.exists():
        return None, "no ahead-of-time kernel (`vo3d compile` builds one)"
    try:
        built = json.loads(stamp_file.read_text())
    except (OSError, ValueError):
        return None, f"{stamp_file} is unreadable"
    now = stamp()
    changed = sorted(k for k in now if built.get(k) != now[k])
    if changed:
        return None, f"the ahead-of-time kernel is stale ({', '.join(changed)} changed)"
    loader = importlib.machinery.ExtensionFileLoader(NAME, str(path))
    spec = importlib.util.spec_from_loader(NAME, loader)
    if spec is None:
        return None, f"{path} cannot be imported"
    module = importlib.util.module_from_spec(spec)
    loader.exec_module(module)
    from . import kernel, swarm

    kernels = Kernels(
        _checked(module.decide, kernel.decide, _decide_args_ok),
        _checked(module.decide_range, swarm.decide_range, _range_args_ok),
    )
    return kernels, f"ahead-of-time kernel {path}"


def _arrays_ok(arrays: tuple, kinds: tuple[tuple[np.dtype, int], ...]) -> bool:
    """Each of ``arrays`` an ndarray of its (dtype, dimensions), C-contiguous."""
    if len(arrays) != len(kinds):
        return False
    for a, (dtype, ndim) in zip(arrays, kinds, strict=True):
        if type(a) is not np.ndarray or a.dtype != dtype or a.ndim != ndim:
            return False
        if not a.flags.c_contiguous:
            return False
    return True


_F8 = np.dtype(np.float64)
_DECIDE_KINDS = tuple((_F8, nd) for nd in DECIDE_NDIMS)
_RANGE_KINDS = tuple((_F8, nd) for nd in RANGE_NDIMS)


def _decide_args_ok(args: tuple) -> bool:
    return _arrays_ok(args, _DECIDE_KINDS) and args[-1].flags.writeable


def _range_args_ok(args: tuple) -> bool:
    from .swarm import SWARM_FIELDS, Swarm

    if len(args) != 3 + len(RANGE_NDIMS) or type(args[0]) is not Swarm:
        return False
    ints = all(isinstance(i, int | np.integer) and not isinstance(i, bool) for i in args[1:3])
    kinds = tuple((np.dtype(dtype), nd) for dtype, nd in SWARM_FIELDS)
    return (
        ints
        and _arrays_ok(tuple(args[0]), kinds)
        and _arrays_ok(args[3:], _RANGE_KINDS)
        and args[-1].flags.writeable
    )


def _checked(compiled: Kernel, jit: Kernel, ok: Callable[[tuple], bool]) -> Kernel:
    """``compiled`` behind a check of its arguments' types: a compiled module does not check
    them (a list where an array belongs would crash the process), so anything else goes to the
    JIT kernel ``jit``, which dispatches on them (and raises where it must)."""

    def call(*args: object) -> None:
        (compiled if ok(args) else jit)(*args)

    call.compiled = compiled  # type: ignore[attr-defined]  # the unchecked call, for timing
    return call
