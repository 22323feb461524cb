"""The decision kernel compiled ahead of time, so that a first ``select()`` does not wait for
numba's JIT (issue 9 §5: 27–50 s with an empty cache on the 2-core test machines).

``build()`` compiles ``kernel.decide`` with numba's ahead-of-time compiler (``numba.pycc``) into
an extension module next to this file (``vo3d compile``; ``make install`` runs it), with a stamp
of what it was built from: the package's sources, the Python, numpy and numba versions and the
CPU (the module is built for this machine's CPU, as numba's JIT would). ``load()`` returns the
compiled ``decide`` only when the stamp matches the running code and machine; otherwise the
selector uses the JIT kernel, so an edited source or a moved environment can never run a stale
or foreign kernel. It is the same code: the functions below ``decide`` are compiled by the same
dispatchers (their flags, ``error_model="numpy"``) and linked into the module, and the answers
are bitwise those of the JIT kernel (tests/test_aot.py).

``numba.pycc`` has been "pending deprecation" since numba 0.57 with no replacement yet; when it
goes, ``build()`` fails with its error and everything runs on the JIT kernel as before.
``select_many`` stays on the JIT (``prange`` over vehicles is not available ahead of time).
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

import numpy as np

#: The extension module's name (its file: NAME + the interpreter's extension suffix).
NAME = "_kernel_aot"
HERE = Path(__file__).resolve().parent
PACKAGE = HERE.parent
#: ``decide``'s arguments: p, v_now, v_pref, nbrs, prisms, limits, options, plane_tab,
#: gen_tab, out (``kernel.decide``), with their dimensions.
NDIMS = (1, 1, 1, 2, 2, 1, 1, 2, 2, 1)
SIGNATURE = "void(" + ", ".join("f8[::1]" if d == 1 else "f8[:, ::1]" for d in NDIMS) + ")"

Decide = Callable[..., None]


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
    from numba.pycc import CC

    from .kernel import decide

    def decide_aot(p, v_now, v_pref, nbrs, prisms, limits, options, plane_tab, gen_tab, out):  # noqa: ANN001
        # only a call: decide and everything below it compile with their own flags
        decide(p, v_now, v_pref, nbrs, prisms, limits, options, plane_tab, gen_tab, out)

    cc = CC(NAME)
    cc.output_dir = directory
    cc.target_cpu = "host"  # as the JIT compiles; the stamp names the CPU
    cc.verbose = False
    cc.export("decide", SIGNATURE)(decide_aot)
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


def load(directory: Path = HERE) -> tuple[Decide | None, str]:
    """The compiled ``decide`` when a module built from this code for this machine is in
    ``directory``, else None; and a sentence saying which. The environment variable
    ``VO3D_AOT=0`` turns it off (the JIT kernel, e.g. to time it)."""
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
    return _checked(module.decide), f"ahead-of-time kernel {path}"


def _checked(compiled: Decide) -> Decide:
    """``compiled`` behind a check of its arguments' types: a compiled module does not check
    them (a list where an array belongs would crash the process), so anything else goes to the
    JIT kernel, which dispatches on them."""
    from .kernel import decide as jit_decide

    f8 = np.dtype(np.float64)

    def decide(*args: np.ndarray) -> None:
        if len(args) != len(NDIMS):
            jit_decide(*args)
            return
        ok = True
        for a, nd in zip(args, NDIMS, strict=True):
            ok = ok and type(a) is np.ndarray and a.dtype == f8 and a.ndim == nd
            ok = ok and a.flags.c_contiguous
        (compiled if ok and args[-1].flags.writeable else jit_decide)(*args)

    decide.compiled = compiled  # type: ignore[attr-defined]  # the unchecked call, for timing
    return decide
