"""Only what pyproject.toml cannot say: the wheel's bundled scenarios.

The repository's top-level ``scenarios/`` folder is the one copy of the bundled scenario files;
it is mapped to the package ``vo3d_opt.scenarios``, so the wheel carries them as package data
(``vo3d_opt/scenarios/*.yaml``, read with ``importlib.resources`` by
``vo3d_opt.sim.scenario.loader.bundled_dir``). Everything else is in pyproject.toml.
"""

from setuptools import find_packages, setup

setup(
    packages=[*find_packages(include=["vo3d_opt", "vo3d_opt.*"]), "vo3d_opt.scenarios"],
    package_dir={"vo3d_opt.scenarios": "scenarios"},
    package_data={"vo3d_opt": ["py.typed"], "vo3d_opt.scenarios": ["*.yaml", "README.md"]},
)
