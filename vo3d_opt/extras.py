"""The optional dependencies (the extras of pyproject.toml) and the one error for a missing one.

The core install (numpy, scipy, pydantic) runs ``select`` and ``select_many`` with the
formulations that need no outside solver: ``plane_qp`` on ``exact2d`` (the default) and
``sampled``. Everything else imports its libraries where it is used, inside :func:`needs`, so
that ``import vo3d_opt`` imports none of them and a missing one is one line naming the extra
that brings it (:class:`MissingExtra`: an ``ImportError``).
"""

from __future__ import annotations

import importlib.util
from collections.abc import Iterator
from contextlib import contextmanager

#: Each extra: the top-level modules this package imports from it (pyproject.toml lists the
#: packages, with their lower bounds).
EXTRAS: dict[str, tuple[str, ...]] = {
    "qp": ("osqp", "clarabel", "daqp", "qpsolvers"),
    "cvxpy": ("cvxpy",),
    "nlp": ("casadi",),
    "sim": ("yaml", "tqdm", "matplotlib", "pyarrow"),
    "rotorpy": ("rotorpy",),
    "sweep": ("dask", "distributed", "pandas", "statsmodels"),
    "batched": ("torch", "torchdiffeq", "roma"),
    "baselines": ("rvo23d",),
    "link": ("pymavlink", "pyproj"),
}

#: Where ``pip install 'vo3d-opt[NAME]'`` alone is not the advice: PyPI's own torch is a CUDA
#: build of several GB, the CPU build comes from PyTorch's index.
_INSTALL = {
    "batched": "pip install torch==2.13.0 --index-url https://download.pytorch.org/whl/cpu, "
    "then pip install 'vo3d-opt[batched]'",
}


def install_command(extra: str) -> str:
    """The command that installs ``extra``."""
    return _INSTALL.get(extra, f"pip install 'vo3d-opt[{extra}]'")


def needs_text(extra: str, modules: tuple[str, ...] = ()) -> str:
    """``needs the [EXTRA] extra (MODULES not installed): COMMAND``: every message ends so."""
    absent = f" ({', '.join(modules)} not installed)" if modules else ""
    return f"needs the [{extra}] extra{absent}: {install_command(extra)}"


class MissingExtra(ImportError, ValueError):
    """``feature`` needs ``extra``, which is not (wholly) installed: one line naming it.

    An ``ImportError``; a ``ValueError`` too, because a solver name that is not installed has
    always been one (the name is well-formed, this machine lacks its library)."""

    def __init__(
        self, feature: str, extra: str, modules: tuple[str, ...] = (), note: str = ""
    ) -> None:
        self.feature, self.extra, self.modules, self.note = feature, extra, modules, note
        super().__init__(
            f"{feature} {needs_text(extra, modules)}{note}", name=modules[0] if modules else None
        )

    def within(self, context: str) -> MissingExtra:
        """The same error for ``context`` (e.g. a formulation) using this feature."""
        return MissingExtra(f"{context} with {self.feature}", self.extra, self.modules, self.note)


def installed(module: str) -> bool:
    """Whether ``module`` can be imported, found without importing it (torch takes seconds);
    a module set to None in ``sys.modules`` (blocked) counts as missing."""
    try:
        return importlib.util.find_spec(module) is not None
    except (ImportError, ValueError):
        return False


def missing(extra: str) -> tuple[str, ...]:
    """The modules of ``extra`` that are not installed (empty when it is complete)."""
    return tuple(m for m in EXTRAS[extra] if not installed(m))


def check(extra: str, feature: str) -> None:
    """Raise :class:`MissingExtra` unless every module of ``extra`` is installed."""
    if absent := missing(extra):
        raise MissingExtra(feature, extra, absent)


@contextmanager
def needs(extra: str, feature: str) -> Iterator[None]:
    """The imports inside this block come from ``extra``: a module that is not there raises
    :class:`MissingExtra` naming it (other import errors, e.g. of a broken install, pass)."""
    try:
        yield
    except ModuleNotFoundError as exc:
        top = (exc.name or "").partition(".")[0]
        raise MissingExtra(feature, extra, (top,) if top else ()) from exc
