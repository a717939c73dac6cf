"""Start-up: ``import sb3_denfac`` and ``sb3-denfac-zoo --help`` import only what they use."""

from __future__ import annotations

import json
import subprocess
import sys

HEAVY = ["torch", "stable_baselines3", "cma", "scipy.stats", "matplotlib.pyplot", "rl_zoo3", "optuna"]


def _modules_after(code: str) -> dict:
    probe = f"{code}\nimport json, sys\nprint(json.dumps({{m: m in sys.modules for m in {HEAVY!r}}}))"
    out = subprocess.run([sys.executable, "-c", probe], capture_output=True, text=True, check=True)
    return json.loads(out.stdout.strip().splitlines()[-1])


def test_import_registers_the_envs_without_the_heavy_modules() -> None:
    code = (
        "import gymnasium as gym, sb3_denfac\n"
        "from sb3_denfac.envs import ALL_ENV_IDS\n"
        "assert all(env_id in gym.registry for env_id in ALL_ENV_IDS), ALL_ENV_IDS\n"
        "assert 'sb3_denfac/ContinuousAcrobot75-v0' in gym.registry"
    )
    assert not any(_modules_after(code).values())


def test_algorithms_load_on_first_use_and_cma_only_with_cmaes() -> None:
    loaded = _modules_after("from sb3_denfac import DENFAC, NFAC, CACLA, DDPG, CMAES, EpisodePerformanceCallback")
    assert loaded["torch"] and loaded["stable_baselines3"]
    assert not loaded["cma"] and not loaded["scipy.stats"]
    with_search = _modules_after("from sb3_denfac import CMAES\nCMAES('MlpPolicy', 'Pendulum-v1')")
    assert with_search["cma"]


def test_zoo_help_imports_neither_the_zoo_nor_torch() -> None:
    code = (
        "import contextlib, io\n"
        "from sb3_denfac.zoo import main\n"
        "with contextlib.redirect_stdout(io.StringIO()) as out:\n"
        "    main(['--help'])\n"
        "assert 'sb3-denfac-zoo {train,optimize,enjoy,record_video}' in out.getvalue()"
    )
    assert not any(_modules_after(code).values())


def test_unknown_attribute_is_an_attribute_error() -> None:
    import pytest

    import sb3_denfac
    import sb3_denfac.zoo

    with pytest.raises(AttributeError, match="no attribute 'DENFACX'"):
        sb3_denfac.DENFACX  # noqa: B018
    with pytest.raises(AttributeError, match="no attribute 'nope'"):
        sb3_denfac.zoo.nope  # noqa: B018
    assert "DENFAC" in dir(sb3_denfac) and "make_model" in dir(sb3_denfac.zoo)
