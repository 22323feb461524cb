"""The built wheel works anywhere: it carries every module, the bundled scenarios
(built from the top-level scenarios/ folder), py.typed and the licence; installed in a fresh
venv, ``vo3d list`` and ``vo3d run`` of a bundled scenario work from outside the repository."""

from __future__ import annotations

import json
import os
import subprocess
import sys
import sysconfig
import zipfile
from pathlib import Path

import pytest

import vo3d_opt

ROOT = Path(__file__).resolve().parents[1]
def _run(cmd: list[str | Path], **kw) -> subprocess.CompletedProcess:
    res = subprocess.run([str(c) for c in cmd], capture_output=True, text=True, timeout=600, **kw)
    assert res.returncode == 0, f"{cmd}\n{res.stdout}\n{res.stderr}"
    return res


@pytest.fixture(scope="module")
def wheel(tmp_path_factory) -> Path:
    """``pip wheel --no-deps .`` of the checkout, in its persistent build directory (``build/``,
    git-ignored; the one ``make install`` builds the compiled core in, so nothing is compiled
    again unless a C++ source changed)."""
    tmp = tmp_path_factory.mktemp("wheel")
    _run(
        [
            sys.executable,
            "-m",
            "pip",
            "wheel",
            "--no-deps",
            "--no-build-isolation",
            "-q",
            "-w",
            tmp / "dist",
            ROOT,
        ]
    )
    (whl,) = (tmp / "dist").glob("vo3d_opt-*.whl")
    return whl


def test_wheel_carries_modules_scenarios_and_metadata(wheel):
    names = set(zipfile.ZipFile(wheel).namelist())
    modules = {p.relative_to(ROOT).as_posix() for p in (ROOT / "vo3d_opt").rglob("*.py")}
    assert modules and modules <= names, sorted(modules - names)  # no subpackage forgotten
    scenarios = {f"vo3d_opt/scenarios/{p.name}" for p in (ROOT / "scenarios").glob("*.yaml")}
    assert scenarios and scenarios <= names, sorted(scenarios - names)
    assert "vo3d_opt/py.typed" in names and "vo3d_opt/_core.pyi" in names
    assert any(n.startswith("vo3d_opt/_core.") and n.endswith((".so", ".pyd")) for n in names)
    assert not any(n.endswith((".cpp", ".hpp", ".pyc")) for n in names)  # built, not shipped
    dist_info = f"vo3d_opt-{vo3d_opt.__version__}.dist-info"
    assert f"{dist_info}/licenses/LICENSE" in names
    metadata = zipfile.ZipFile(wheel).read(f"{dist_info}/METADATA").decode()
    assert "License-Expression: MIT" in metadata and f"Version: {vo3d_opt.__version__}" in metadata


def test_installed_wheel_runs_bundled_scenarios_outside_the_repo(wheel, tmp_path):
    # A fresh venv with the wheel only; the dependencies come from this venv's site-packages
    # (a .pth line), so nothing is downloaded and the repository is not on the path.
    venv = tmp_path / "venv"
    _run([sys.executable, "-m", "venv", "--without-pip", venv])
    python = venv / "bin" / "python"
    site = Path(
        _run(
            [python, "-c", "import sysconfig; print(sysconfig.get_paths()['purelib'])"]
        ).stdout.strip()
    )
    (site / "deps.pth").write_text(sysconfig.get_paths()["purelib"] + "\n")
    _run([sys.executable, "-m", "pip", "--python", python, "install", "--no-deps", "-q", wheel])
    work = tmp_path / "elsewhere"
    work.mkdir()
    env = {k: v for k, v in os.environ.items() if k != "PYTHONPATH"}
    env["PYTHONWARNINGS"] = "ignore"

    where = _run(
        [
            python,
            "-c",
            "import vo3d_opt; from vo3d_opt.sim.scenario import bundled_dir; "
            "print(vo3d_opt.__file__); print(bundled_dir())",
        ],
        cwd=work,
        env=env,
    ).stdout
    assert str(ROOT) not in where and str(venv) in where, where

    vo3d = venv / "bin" / "vo3d"
    assert (
        _run([vo3d, "--version"], cwd=work, env=env).stdout.strip()
        == f"vo3d {vo3d_opt.__version__}"
    )
    listed = json.loads(_run([vo3d, "list", "--json"], cwd=work, env=env).stdout)
    assert {r["name"] for r in listed} == {p.stem for p in (ROOT / "scenarios").glob("*.yaml")}
    summary = json.loads(
        _run([vo3d, "run", "paper-flight-test", "--json", "-q"], cwd=work, env=env).stdout
    )
    assert summary["scenario"] == "paper-flight-test" and summary["all_reached"]
    ran = _run(
        [
            python,
            "-c",
            "from vo3d_opt.sim.simulator import run_scenario; "
            "print(run_scenario('vertical-encounter', max_steps=2, progress=False).steps)",
        ],
        cwd=work,
        env=env,
    ).stdout
    assert ran.strip() == "2"


#: In the fresh venv: the README's one-call example and its 100-vehicle ``select_many``, run from
#: the README's own code blocks, each first call timed (printed, never asserted).
FIRST_MINUTES = """
import json, re, sys, time
readme = open(sys.argv[1], encoding="utf-8").read()
blocks = re.findall(r"```python\\n(.*?)```", readme, re.S)
one_call = next(b for b in blocks if "selector.select(" in b)
swarm = next(b for b in blocks if ".select_many(" in b)
t0 = time.perf_counter()
import vo3d_opt
t1 = time.perf_counter()
ns = {}
exec(one_call, ns)  # the imports, the constructor, the first select() and its print
t2 = time.perf_counter()
exec(swarm, ns)  # the first select_many(), 100 vehicles
t3 = time.perf_counter()
extras = json.loads(sys.argv[2])
print(json.dumps({
    "status": ns["decision"].status, "swarm": list(ns["swarm"].velocities.shape),
    "loaded": [m for m in extras if m in sys.modules],
    "times": f"import vo3d_opt {t1 - t0:.3f} s, README one call {t2 - t1:.3f} s "
             f"(select() itself {ns['decision'].solve_time * 1e3:.2f} ms), 100-vehicle "
             f"select_many {t3 - t2:.3f} s (the call itself {ns['swarm'].solve_time * 1e3:.1f} ms)",
}))
"""


@pytest.mark.install
def test_first_minutes_of_a_plain_install(wheel, tmp_path, record_property):
    """The wheel with no extra in a fresh venv (its dependencies from the package index), then the
    README's examples in a fresh process outside the repository; a missing extra is one line."""
    from vo3d_opt.extras import EXTRAS

    venv = tmp_path / "core"
    _run([sys.executable, "-m", "venv", "--without-pip", venv])
    python = venv / "bin" / "python"
    _run([sys.executable, "-m", "pip", "--python", python, "install", "-q", wheel])
    listed = _run([sys.executable, "-m", "pip", "--python", python, "list", "--format", "json"])
    names = {p["name"].lower().replace("_", "-") for p in json.loads(listed.stdout)}
    assert {"vo3d-opt", "numpy", "scipy", "pydantic"} <= names and len(names) <= 25, names
    assert not names & {"pyyaml", "matplotlib", "pandas", "casadi", "cvxpy", "rotorpy"}

    env = {k: v for k, v in os.environ.items() if k != "PYTHONPATH"}
    extra_modules = sorted({m for modules in EXTRAS.values() for m in modules})
    out = json.loads(
        _run(
            [python, "-c", FIRST_MINUTES, ROOT / "README.md", json.dumps(extra_modules)],
            cwd=tmp_path,
            env=env,
        ).stdout.splitlines()[-1]
    )
    print(f"first minutes: {len(names)} packages; {out['times']}")
    record_property("first_minutes", f"{len(names)} packages; {out['times']}")
    assert out["status"] == "optimal" and out["swarm"] == [100, 3] and out["loaded"] == []

    # without [sim], vo3d says so in one line; the nlp formulation's solver ([nlp]) as well
    res = subprocess.run([venv / "bin" / "vo3d", "list"], capture_output=True, text=True, env=env)
    assert res.returncode == 2 and len(res.stderr.strip().splitlines()) == 1
    assert "[sim]" in res.stderr and "pip install 'vo3d-opt[sim]'" in res.stderr
    code = "from vo3d_opt import VelocitySelector\ntry:\n    VelocitySelector('nlp')\n"
    code += "except ImportError as exc:\n    print(exc)"
    said = _run([python, "-c", code], cwd=tmp_path, env=env).stdout.strip()
    assert "[nlp]" in said and "\n" not in said, said
