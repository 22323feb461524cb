"""The lean core: ``import vo3d_opt``, ``select`` and ``select_many`` import none of the extras'
libraries, and a feature whose extra is missing says so in one line naming it (the library: an
``ImportError``; ``vo3d``: exit 2). Missing libraries are simulated in a child process by
blocking their import (``sys.modules[name] = None``, which Python's import treats as absent);
``tests/test_packaging.py`` installs the wheel with no extra at all."""

from __future__ import annotations

import json
import subprocess
import sys

import pytest

from vo3d_opt.extras import EXTRAS

#: The top-level modules of every extra, and those they bring that the core must not import.
EXTRA_MODULES = sorted(
    {m for modules in EXTRAS.values() for m in modules}
    | {"osqp", "clarabel", "daqp", "qpsolvers", "cvxpy", "casadi", "yaml", "matplotlib"}
    | {"pandas", "pyarrow", "dask", "rotorpy", "torch", "pymavlink", "pyproj", "tqdm", "PIL"}
)


def _child(code: str, *, block: tuple[str, ...] = ()) -> subprocess.CompletedProcess:
    """``code`` in a fresh interpreter with ``block`` made unimportable first."""
    prelude = "import sys\n" + "".join(f"sys.modules[{m!r}] = None\n" for m in block)
    return subprocess.run(
        [sys.executable, "-c", prelude + code], capture_output=True, text=True, timeout=120
    )


def _json(res: subprocess.CompletedProcess) -> dict:
    assert res.returncode == 0, res.stderr[-3000:]
    return json.loads(res.stdout.strip().splitlines()[-1])


DECISIONS = """
import json
import numpy as np
import vo3d_opt
from vo3d_opt import AgentState, Cylinder, Limits, Neighbor, VelocitySelector

EXTRAS = json.loads(sys.argv[1])
kw = dict(own=AgentState(position=(0, 0, 20), velocity=(4, 0, 0)), preferred_velocity=(4, 0, 0),
          neighbors=[Neighbor(position=(30, 0, 20), velocity=(-4, 0, 0), r_pz=10)],
          obstacles=[Cylinder(center=(15, 1), radius=2, height=30)],
          limits=Limits(speed=(0, 4), altitude=(0, 40)), dt=0.2)
out = {"after_import": [m for m in EXTRAS if m in sys.modules]}
statuses = [VelocitySelector(f).select(**kw).status for f in ("plane_qp", "sampled")]
P = np.random.default_rng(0).uniform((0, 0, 10), (100, 100, 30), size=(20, 3))
many = VelocitySelector().select_many(P, np.zeros((20, 3)), np.tile((4.0, 0, 0), (20, 1)), 8.0,
                                      limits=Limits(speed=(0, 4), altitude=(0, 40)), dt=0.2,
                                      sensing_range=55.0)
out["statuses"] = statuses + [str(s) for s in many.statuses]
out["after_decisions"] = [m for m in EXTRAS if m in sys.modules]
import vo3d_opt.sim  # the check itself: the simulator does import [sim]'s libraries
out["after_sim"] = [m for m in EXTRAS if m in sys.modules]
print(json.dumps(out))
"""


def test_import_and_decisions_import_no_extra():
    res = subprocess.run(
        [sys.executable, "-c", "import sys\n" + DECISIONS, json.dumps(EXTRA_MODULES)],
        capture_output=True,
        text=True,
        timeout=120,
    )
    out = _json(res)
    assert out["after_import"] == [] and out["after_decisions"] == []
    assert out["statuses"][:2] == ["optimal", "optimal"] and len(out["statuses"]) == 22
    assert {"yaml", "tqdm"} <= set(out["after_sim"])  # the same probe sees an extra imported


#: The library's features that need an extra, each with the modules blocked for it and the
#: extra its error must name. ``small`` is a two-vehicle scenario built without YAML.
FEATURES = """
import importlib, json, tempfile
from pathlib import Path

SMALL = {"name": "small", "dt": 0.2, "max_time": 1.0,
         "limits": {"speed": [0.0, 4.0], "altitude": [0.0, 40.0]},
         "agents": [{"id": "a", "start": [0.0, 0.0, 20.0], "goal": [20.0, 0.0, 20.0]},
                    {"id": "b", "start": [20.0, 5.0, 20.0], "goal": [0.0, 5.0, 20.0]}]}


def small():
    from vo3d_opt.sim.scenario import scenario_from_dict
    return scenario_from_dict(SMALL)


def parquet():
    from vo3d_opt.report import write_parquet
    from vo3d_opt.sim.simulator import run_scenario
    record = run_scenario(small(), max_steps=1, progress=False)
    write_parquet(record, Path(tempfile.mkdtemp()) / "t.parquet")


def selector(*args):
    from vo3d_opt import VelocitySelector
    return VelocitySelector(*args)


def dynamics(name, *args):
    return getattr(importlib.import_module("vo3d_opt.sim.rotorpy_models"), name)(*args)


def rvo2():
    from vo3d_opt.baselines import run_rvo2
    run_rvo2(small(), max_steps=1, progress=False)


def mavlink():
    from vo3d_opt.link.messages import mavlink
    mavlink()


def geodesy():
    from vo3d_opt.link.frames import GeodeticFrame
    GeodeticFrame(0.0, 0.0, 0.0)


def scenario_key():
    from vo3d_opt.sim.scenario import scenario_from_dict
    scenario_from_dict({**SMALL, "dynamics": {"model": "rotorpy"}})


CASES = {
    "plane_qp on osqp": lambda: selector("plane_qp", "osqp"),
    "cone_qp's default": lambda: selector("cone_qp"),
    "qpsolvers": lambda: selector("cone_qp", "qpsolvers:quadprog"),
    "cvxpy": lambda: selector("cone_qp", "cvxpy"),
    "nlp": lambda: selector("nlp"),
    "figures": lambda: importlib.import_module("vo3d_opt.figures"),
    "animation": lambda: importlib.import_module("vo3d_opt.animation"),
    "parquet": parquet,
    "rotorpy": lambda: dynamics("RotorPyDynamics"),
    "rotorpy key": scenario_key,
    "batched": lambda: dynamics("BatchedRotorPyDynamics"),
    "sweep": lambda: importlib.import_module("vo3d_opt.sweep").run_sweep("pair", 1),
    "rvo2": rvo2,
    "mavlink": mavlink,
    "geodesy": geodesy,
}
out = {}
for name, case in CASES.items():
    try:
        case()
        out[name] = None
    except Exception as exc:
        out[name] = {"import": isinstance(exc, ImportError), "value": isinstance(exc, ValueError),
                     "message": str(exc)}
print(json.dumps(out))
"""

#: What each case's error must name, and whether it is an ImportError (else a ValueError: a
#: scenario key that names the extra, checked when the configuration is read).
EXPECTED = {
    "plane_qp on osqp": ("[qp]", True),
    "cone_qp's default": ("[qp]", True),
    "qpsolvers": ("[qp]", True),
    "cvxpy": ("[cvxpy]", True),
    "nlp": ("[nlp]", True),
    "figures": ("[sim]", True),
    "animation": ("[sim]", True),
    "parquet": ("[sim]", True),
    "rotorpy": ("[rotorpy]", True),
    "rotorpy key": ("[rotorpy]", False),
    "batched": ("[batched]", True),
    "sweep": ("[sweep]", True),
    "rvo2": ("[baselines]", True),
    "mavlink": ("[link]", True),
    "geodesy": ("[link]", True),
}

BLOCKED = (
    *("osqp", "clarabel", "daqp", "qpsolvers", "cvxpy", "casadi", "matplotlib", "pyarrow"),
    *("rotorpy", "torch", "dask", "distributed", "statsmodels", "rvo23d", "pymavlink", "pyproj"),
)


def test_a_missing_extra_is_one_line_naming_it():
    out = _json(_child(FEATURES, block=BLOCKED))
    assert set(out) == set(EXPECTED)
    for name, (extra, is_import_error) in EXPECTED.items():
        err = out[name]
        assert err is not None, f"{name}: ran without its extra"
        msg = err["message"]
        assert extra in msg and "pip install" in msg and "\n" not in msg, (name, msg)
        assert err["import"] is is_import_error and (is_import_error or err["value"]), (name, err)
    # a solver name is a ValueError too, listing what is available
    assert out["plane_qp on osqp"]["value"]
    assert out["plane_qp on osqp"]["message"].startswith(
        "formulation 'plane_qp' with solver 'osqp' needs the [qp] extra (osqp not installed)"
    )
    assert "available: exact2d" in out["plane_qp on osqp"]["message"]



QP_EXTRA = """
import json
from vo3d_opt import VelocitySelector
out = {}
for name in ("proxqp", "quadprog", "piqp"):
    try:
        VelocitySelector("cone_qp", f"qpsolvers:{name}")
        out[name] = None
    except ValueError as exc:
        out[name] = {"import": isinstance(exc, ImportError), "message": str(exc)}
print(json.dumps(out))
"""


def test_a_qpsolvers_solver_of_the_qp_extra_names_it():
    """qpsolvers comes with the core install, proxqp, quadprog and piqp with ``[qp]``: asking
    for one of those without it names the extra and the library, not only 'uninstalled'."""
    out = _json(_child(QP_EXTRA, block=("proxsuite", "quadprog", "piqp")))
    for name, library in (("proxqp", "proxsuite"), ("quadprog", "quadprog"), ("piqp", "piqp")):
        err = out[name]
        assert err is not None and err["import"], (name, err)
        assert f"needs the [qp] extra ({library} not installed)" in err["message"], err

SIM_MISSING = """
import json
try:
    import vo3d_opt.sim
    library = None
except ImportError as exc:
    library = str(exc)
from vo3d_opt.cli import main
print(json.dumps({"library": library, "status": main(sys.argv[1:])}))
"""


@pytest.mark.parametrize(
    ("block", "argv", "extra"),
    [
        (("yaml",), ["list"], "[sim]"),
        (("yaml",), ["--version"], "[sim]"),
        (("osqp",), ["run", "paper-flight-test", "--solver", "osqp", "--json"], "[qp]"),
        (("distributed",), ["sweep", "pair", "--n", "1"], "[sweep]"),
    ],
    ids=["no-sim", "no-sim-version", "no-qp", "no-sweep"],
)
def test_vo3d_without_an_extra_exits_2_with_one_line_naming_it(block, argv, extra):
    prelude = "import sys\n" + "".join(f"sys.modules[{m!r}] = None\n" for m in block)
    res = subprocess.run(
        [sys.executable, "-c", prelude + SIM_MISSING, *argv],
        capture_output=True,
        text=True,
        timeout=120,
    )
    out = _json(res)
    assert out["status"] == 2
    lines = res.stderr.strip().splitlines()
    assert len(lines) == 1 and extra in lines[0] and "pip install" in lines[0], res.stderr
    if block == ("yaml",):
        assert "[sim]" in out["library"] and "\n" not in out["library"]
