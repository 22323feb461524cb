"""The registry: solver names (strings the user passes) to backends, like qpsolvers.

Accepted names:

- ``"exact2d"``: this package's exact solver of the per-plane problem (nearest point to the
  preferred velocity inside the speed disc and half-planes; ``solvers/exact2d.py``);
- ``"osqp"``, ``"clarabel"``, ``"daqp"``: the solvers' own Python APIs;
- ``"cvxpy"`` (cvxpy picks the solver) and ``"cvxpy:<SOLVER>"`` for any installed cvxpy solver
  that accepts a quadratic objective;
- ``"qpsolvers:<name>"`` for every name in ``qpsolvers.available_solvers``;
- ``"casadi"`` (plugin ipopt) and ``"casadi:<plugin>"`` for the non-convex NLP.

``exact2d``, osqp, clarabel, daqp and qpsolvers come with the core install; qpsolvers'
proxqp, quadprog and piqp with the extra ``[qp]``, cvxpy with ``[cvxpy]``, CasADi with
``[nlp]``. The name of a solver whose library is not installed raises
:class:`~vo3d_opt.extras.MissingExtra`, one line naming the extra (an ImportError, and a
ValueError as every unavailable name). Backend modules are
imported lazily, so importing this package stays cheap.
"""

from __future__ import annotations

import functools

from vo3d_opt.extras import EXTRAS, MissingExtra, installed
from vo3d_opt.solvers.base import Backend

#: Plugins of ``casadi.nlpsol`` this package knows how to run quietly (see casadi_backend).
CASADI_PLUGINS = ("ipopt", "sqpmethod")

#: The extra that brings each solver library (the prefix of its solver names).
_SOLVER_EXTRAS = {module: extra for extra in ("qp", "cvxpy", "nlp") for module in EXTRAS[extra]}
#: The qpsolvers solvers the ``[qp]`` extra brings, by their modules.
_QP_EXTRA_SOLVERS = {"proxqp": "proxsuite", "quadprog": "quadprog", "piqp": "piqp"}

_CACHE: dict[str, Backend] = {}
_REGISTERED: dict[str, Backend] = {}


@functools.cache
def _cvxpy_solvers() -> dict[str, bool]:
    """Installed cvxpy solvers that take a quadratic objective -> whether they take a SOC."""
    if not installed("cvxpy"):
        return {}
    import cvxpy as cp
    from cvxpy.constraints import SOC
    from cvxpy.reductions.solvers.defines import QP_SOLVERS, SOLVER_MAP_CONIC

    found: dict[str, bool] = {}
    for name in cp.installed_solvers():
        conic = SOLVER_MAP_CONIC.get(name)
        socp = conic is not None and SOC in conic.SUPPORTED_CONSTRAINTS
        if name in QP_SOLVERS or socp or (conic is not None and conic.supports_quad_obj()):
            found[name] = socp
    return found


@functools.cache
def _qpsolvers_solvers() -> tuple[str, ...]:
    if not installed("qpsolvers"):
        return ()
    import qpsolvers

    return tuple(sorted(qpsolvers.available_solvers))


@functools.cache
def _casadi_plugins() -> tuple[str, ...]:
    if not installed("casadi"):
        return ()
    import casadi

    return tuple(p for p in CASADI_PLUGINS if casadi.has_nlpsol(p))


@functools.cache
def _builtin_names() -> tuple[str, ...]:
    names = ["exact2d"] + [n for n in ("osqp", "clarabel", "daqp") if installed(n)]
    if cvx := _cvxpy_solvers():
        names += ["cvxpy"] + [f"cvxpy:{s}" for s in sorted(cvx)]
    names += [f"qpsolvers:{s}" for s in _qpsolvers_solvers()]
    if plugins := _casadi_plugins():
        names += ["casadi"] + [f"casadi:{p}" for p in plugins]
    return tuple(names)


def available_solvers() -> list[str]:
    """Every name :func:`get_backend` accepts here (installed solvers and registered ones)."""
    return list(_builtin_names()) + [n for n in _REGISTERED if n not in _builtin_names()]


def available_qp_solvers() -> list[str]:
    """The names in :func:`available_solvers` whose backend solves QPs (kind "qp")."""
    return [
        n
        for n in available_solvers()
        if (n in _REGISTERED and _REGISTERED[n].kind == "qp")
        or (n not in _REGISTERED and not n.startswith("casadi"))
    ]


def _canonical(name: str) -> str:
    """Lower-case prefix; cvxpy solver names upper-case, the others lower-case."""
    prefix, _, suffix = name.strip().partition(":")
    prefix, suffix = prefix.strip().lower(), suffix.strip()
    suffix = suffix.upper() if prefix == "cvxpy" else suffix.lower()
    return f"{prefix}:{suffix}" if suffix else prefix


def _unknown(name: str) -> ValueError:
    """ValueError listing the available names; :class:`MissingExtra` (a ValueError too) naming
    the extra when the name is one of a solver library that is not installed."""
    available = ", ".join(available_solvers())
    module = name.partition(":")[0]
    if module in _SOLVER_EXTRAS and not installed(module):
        extra = _SOLVER_EXTRAS[module]
        return MissingExtra(f"solver {name!r}", extra, (module,), f"; available: {available}")
    library = _QP_EXTRA_SOLVERS.get(name.partition(":")[2]) if module == "qpsolvers" else None
    if library is not None and not installed(library):
        return MissingExtra(f"solver {name!r}", "qp", (library,), f"; available: {available}")
    return ValueError(f"unknown or uninstalled solver {name!r}; available: {available}")


def _construct(name: str) -> Backend:
    """A new backend for a canonical name, or ValueError when it is not available."""
    prefix, _, suffix = name.partition(":")
    if name == "exact2d":
        from vo3d_opt.solvers.exact2d import Exact2DBackend

        return Exact2DBackend()
    if name == "osqp" and installed("osqp"):
        from vo3d_opt.solvers.osqp_backend import OsqpBackend

        return OsqpBackend()
    if name == "clarabel" and installed("clarabel"):
        from vo3d_opt.solvers.clarabel_backend import ClarabelBackend

        return ClarabelBackend()
    if name == "daqp" and installed("daqp"):
        from vo3d_opt.solvers.daqp_backend import DaqpBackend

        return DaqpBackend()
    if prefix == "cvxpy" and (solvers := _cvxpy_solvers()) and (suffix in solvers or not suffix):
        from vo3d_opt.solvers.cvxpy_backend import CvxpyBackend

        has_cones = solvers[suffix] if suffix else any(solvers.values())
        return CvxpyBackend(name, suffix or None, has_cones)
    if prefix == "qpsolvers" and suffix in _qpsolvers_solvers():
        from vo3d_opt.solvers.qpsolvers_backend import QpsolversBackend

        return QpsolversBackend(name, suffix)
    if prefix == "casadi" and (suffix or "ipopt") in _casadi_plugins():
        from vo3d_opt.solvers.casadi_backend import CasadiBackend

        return CasadiBackend(name, suffix or "ipopt")
    raise _unknown(name)


def get_backend(name: str) -> Backend:
    """The (cached) backend for a solver name; ValueError listing the available names if unknown."""
    if not isinstance(name, str):
        raise ValueError(f"solver must be a string, got {type(name).__name__}")
    if name in _REGISTERED:
        return _REGISTERED[name]
    key = _canonical(name)
    if key in _REGISTERED:
        return _REGISTERED[key]
    if key not in _CACHE:
        _CACHE[key] = _construct(key)
    return _CACHE[key]


def register_backend(name: str, backend: Backend) -> None:
    """Make ``get_backend(name)`` return ``backend`` (e.g. a deliberately failing one in tests)."""
    if not isinstance(backend, Backend):
        raise ValueError(f"backend must be a Backend, got {type(backend).__name__}")
    _REGISTERED[name] = backend


def unregister_backend(name: str) -> None:
    """Undo :func:`register_backend` (a no-op for names never registered)."""
    _REGISTERED.pop(name, None)
