"""The batched RotorPy vehicles of many runs in one ``BatchedMultirotor``.

A RotorPy encounter of a few vehicles spends nearly all of its time in torch's cost per call,
which hardly grows with the vehicles of a call (``docs/results/dynamics.md``: per vehicle and
period about 20 ms for 8 vehicles, under 1 ms for 500). A :class:`RotorPyFleet` steps the
vehicles of many runs in one call per sub-step, each run flown by ``fly`` in a thread of its
own: each run's model (a ``BatchedRotorPyDynamics`` made with ``fleet=``) hands the fleet its
period and waits; when every model still flying has done so, the last one in flies them all.
A run whose flight is over ``leave``-s, and the others go on without it; ``abort`` ends every
run at its next period (after a Ctrl-C of the thread that waits for them).

A vehicle's numbers do not depend on who else flies: RotorPy's batched dynamics is arithmetic
row by row (tests/test_rotorpy_fleet.py flies runs in a fleet and each alone, bit for bit), and
each model keeps its own wind objects and numpy stream. RotorPy's batched motor noise would
draw from the fleet's torch stream: only vehicles without it (both of ours) join a fleet.
"""

from __future__ import annotations

import threading
from typing import TYPE_CHECKING, Any

import numpy as np

from vo3d_opt.extras import needs

if TYPE_CHECKING:
    from vo3d_opt.sim.rotorpy_models import BatchedRotorPyDynamics, Period


def import_torch() -> Any:
    """torch, after checking that the rest of the ``batched`` extra (torchdiffeq, roma, which
    RotorPy's batched vehicles import) is there too; a ``MissingExtra`` (a ``ValueError``)
    naming the key if not."""
    with needs("batched", "dynamics.batched:"):
        import roma  # noqa: F401 - imported by RotorPy's batched vehicles
        import torch
        import torchdiffeq  # noqa: F401 - the same
    return torch


class FleetStepError(RuntimeError):
    """A step of the fleet failed: each run that waited for it gets one of these (the cause
    chained); flown alone, a run that did not cause it flies on."""


class FleetAborted(RuntimeError):
    """The fleet was aborted (:meth:`RotorPyFleet.abort`): raised in each of its runs at its
    next period."""


class RotorPyFleet:
    """One ``BatchedMultirotor`` for the models that ``join`` it, stepped when all of those
    still flying asked for a period (the module docstring). All fly one vehicle type; the
    periods stepped together must have one sub-step length."""

    def __init__(self, seed: int = 0) -> None:
        self.torch = import_torch()
        self._cond = threading.Condition()
        self._members: list[BatchedRotorPyDynamics] = []  # in joining order
        self._flying: set[int] = set()  # id() of the members that did not leave
        self._asked: dict[int, Period] = {}
        self._failed: dict[int, tuple[BaseException, bool]] = {}  # error, step shared
        self._vehicles: dict[int, Any] = {}  # BatchedMultirotor by number of vehicles
        self._aborted = False
        self.reseed(seed)

    def join(self, model: BatchedRotorPyDynamics) -> None:
        """Count ``model`` among the members: the fleet waits for it until it leaves."""
        with self._cond:
            if self._members and model.vehicle != self._members[0].vehicle:
                raise ValueError(
                    f"vehicle: a fleet flies one vehicle type ({self._members[0].vehicle}), "
                    f"got {model.vehicle!r}"
                )
            self._members.append(model)
            self._flying.add(id(model))

    def leave(self, model: BatchedRotorPyDynamics) -> None:
        """``model``'s run is over: the others step without it from now on."""
        with self._cond:
            self._flying.discard(id(model))
            self._fly_when_all_asked(caller=None)

    def abort(self) -> None:
        """End every run: each waiting for its period, and each asking for one from now on,
        gets :class:`FleetAborted` (a step in progress ends first). For the thread that started
        the runs, on a Ctrl-C: otherwise they fly on to their end, and the process with them."""
        with self._cond:
            self._aborted = True
            self._asked.clear()
            self._cond.notify_all()

    def reseed(self, seed: int) -> None:
        """Start the fleet's torch stream again from ``seed``."""
        with self.torch.random.fork_rng(devices=[]):
            self.torch.manual_seed(seed)
            self._torch_rng = self.torch.random.get_rng_state()

    def fly(self, model: BatchedRotorPyDynamics, period: Period) -> None:
        """Fill ``period``'s samples once every member still flying asked for its own."""
        with self._cond:
            if id(model) not in self._flying:
                raise RuntimeError("a model that left its fleet cannot step again")
            if not self._aborted:
                self._asked[id(model)] = period
                self._fly_when_all_asked(caller=id(model))
            while id(model) in self._asked:
                self._cond.wait()
            failure, shared = self._failed.pop(id(model), (None, False))
            aborted = self._aborted
        if failure is None:
            if aborted:
                raise FleetAborted("the fleet was aborted")
            return
        if not shared:  # a fleet of this model alone: its own error, as it is
            raise failure
        name = type(failure).__name__
        raise FleetStepError(f"the fleet's step failed: {name}: {failure}") from failure

    def _fly_when_all_asked(self, caller: int | None) -> None:
        # called with the lock held; whoever completes the set flies it and wakes the others
        if not self._asked or len(self._asked) < len(self._flying):
            return
        batch = [m for m in self._members if id(m) in self._asked]
        try:
            self._fly_all(batch, [self._asked[id(m)] for m in batch])
        except BaseException as exc:  # every waiting run gets the error, none waits forever
            # a Ctrl-C goes up the caller's own stack; the others get it as their failure
            mine, shared = isinstance(exc, Exception), len(batch) > 1
            self._failed.update({id(m): (exc, shared) for m in batch if mine or id(m) != caller})
            if not mine:
                raise
        finally:
            self._asked.clear()
            self._cond.notify_all()

    def _fly_all(self, batch: list[BatchedRotorPyDynamics], periods: list[Period]) -> None:
        """Fill the samples of each member's period: every sub-step, each member's winds into
        its state rows, then one call for all the active vehicles."""
        first = periods[0]
        if any(p.substeps != first.substeps or p.h != first.h for p in periods):
            raise ValueError("dt: the runs of one fleet step with one period and sub-step rate")
        h = first.h
        winds = [m.period_winds(p) for m, p in zip(batch, periods, strict=True)]
        moving = [(m, p) for m, p in zip(batch, periods, strict=True) if p.active.size]
        for k in range(first.substeps):
            for m, p, w in zip(batch, periods, winds, strict=True):
                if w is not None:
                    m.state["wind"][p.active] = self.torch.from_numpy(w[k])
            if moving:
                self._substep(moving, k, h)
            for m, p in zip(batch, periods, strict=True):
                p.p_out[k], p.v_out[k] = m.state["x"].numpy(), m.state["v"].numpy()

    def _substep(
        self, moving: list[tuple[BatchedRotorPyDynamics, Period]], k: int, h: float
    ) -> None:
        """One RK4 sub-step of the active vehicles of ``moving``, all in one call."""
        torch = self.torch
        lo = np.cumsum([0] + [m.n for m, _ in moving])
        if len(moving) == 1:
            state = moving[0][0].state
        else:
            state = {
                key: torch.cat([m.state[key] for m, _ in moving]) for key in moving[0][0].state
            }
        cmd = np.concatenate([p.command(k) for _, p in moving])
        idxs = np.concatenate([p.active + lo[j] for j, (_, p) in enumerate(moving)])
        vehicles = self._vehicles_for(moving[0][0], state)
        with torch.random.fork_rng(devices=[]), torch.no_grad():
            torch.random.set_rng_state(self._torch_rng)
            # RotorPy returns NaN rows for the vehicles it does not step (the held ones):
            # never stepped again (a release starts them from hover), and _end overwrites
            # their samples
            new = vehicles.step(
                state, {"cmd_v": torch.from_numpy(cmd)}, h, idxs=torch.from_numpy(idxs)
            )
            self._torch_rng = torch.random.get_rng_state()
        for j, (m, _) in enumerate(moving):
            m.state = {key: value[lo[j] : lo[j + 1]] for key, value in new.items()}

    def _vehicles_for(self, model: BatchedRotorPyDynamics, state: dict[str, Any]) -> Any:
        """A ``BatchedMultirotor`` of the fleet's vehicle for the rows of ``state`` (it keeps
        no state of its own: one per number of vehicles serves every step of that size; the
        size changes as runs leave and vehicles are held, a few dozen sizes a fleet)."""
        from rotorpy.vehicles.multirotor import BatchedMultirotor, BatchedMultirotorParams

        n = int(state["x"].shape[0])
        if n not in self._vehicles:
            cpu = self.torch.device("cpu")
            self._vehicles[n] = BatchedMultirotor(
                BatchedMultirotorParams([model.params] * n, n, cpu),
                n,
                state,
                cpu,
                control_abstraction="cmd_vel",
                integrator="rk4",
            )
        return self._vehicles[n]
