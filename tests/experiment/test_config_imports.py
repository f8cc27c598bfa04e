"""The config schema reads without torch: its registries' names, the rewards' defaults, the
scenarios and the model's parameters all have torch-free homes."""

from __future__ import annotations

import subprocess
import sys

LIGHT = (
    "vdtn_marl.experiment.config",
    "vdtn_marl.experiment.compose",
    "vdtn_marl.policies.registry",
    "vdtn_marl.voi.registry",
    "vdtn_marl.core.reward",
    "vdtn_marl.algos.trainer",
    "vdtn_marl.scenarios",
    "vdtn_marl.sim.params",
)


def _fresh(code: str) -> str:
    """stdout of ``code`` in a fresh interpreter (this one has torch already)."""
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True)
    assert done.returncode == 0, done.stderr
    return done.stdout.strip()


def test_the_schema_and_its_registries_import_no_torch():
    code = (
        "import importlib, sys\n"
        f"for name in {LIGHT!r}:\n"
        "    importlib.import_module(name)\n"
        "print('torch' in sys.modules)\n"
    )
    assert _fresh(code) == "False"


def test_composing_a_default_run_config_imports_no_torch():
    """Hydra composes the default job into a :class:`RunConfig` whose choices come from the
    registries, and the model of its scenario is built, all without torch. (``validate``
    imports it: the leader trace sets it checks are torch samplers, and the device check asks
    torch.)"""
    code = (
        "import sys\n"
        "from vdtn_marl.experiment import compose, config\n"
        "with compose.hydra_compose():\n"
        "    cfg = compose.compose_config('config', [])\n"
        "run = config.from_dict(compose.job_config(cfg))\n"
        "assert run == config.RunConfig() and run.rra.kappa1 == config.RRAReward.kappa1\n"
        "assert 'greedy' in config.RRA_METHODS and 'oracle' in config.CONTROLS\n"
        "assert 'rollout' in config.IVOI_ESTIMATORS\n"
        "assert run.twin_params().platoon.num_vehicles == run.scenario.num_vehicles\n"
        "print('torch' in sys.modules)\n"
    )
    assert _fresh(code) == "False"


def test_composing_from_python_shows_no_hydra_schema_warning():
    """Hydra warns that our launcher configs share their schemas' names on every composition;
    nothing for a user to act on, so composing from Python (benchmarks, notebooks) is quiet,
    as the command line is."""
    code = (
        "import warnings\n"
        "warnings.simplefilter('always')\n"
        "from vdtn_marl.experiment import compose\n"
        "with warnings.catch_warnings(record=True) as seen:\n"
        "    warnings.simplefilter('always')\n"
        "    with compose.hydra_compose():\n"
        "        compose.compose_config('config', ['experiment=smoke'])\n"
        "print(sum('ConfigStore schema' in str(w.message) for w in seen))\n"
    )
    assert _fresh(code) == "0"
