import gymnasium as gym
import pytest
import torch as th

import shelf_env  # noqa: F401
from shelf_env.world.cabinet import Region
from shelf_env.world.objects import ObjectSpec

# The test networks are tiny; one thread is as fast, and several OpenMP threads spin badly when
# another process (a training run, a parallel job) shares the two cores.
th.set_num_threads(1)

# Three side-by-side regions spanning the full depth: left (+y) green, middle yellow, right blue.
REGIONS = [Region(0.0, 0.40, 0.12, 0.30), Region(0.0, 0.40, -0.09, 0.09), Region(0.0, 0.40, -0.30, -0.12)]


def box(sx=0.06, sy=0.06, h=0.08, mass=0.3) -> ObjectSpec:
    return ObjectSpec("cuboid", "box", (sx, sy, h), mass)


@pytest.fixture
def env():
    e = gym.make("ShelfSort-v0", num_objects=3).unwrapped
    e.reset(seed=0)
    yield e
    e.close()


def action_at(env, map_name: str, x: float, y: float) -> int:
    """Flat action index of the cell containing cabinet point (x, y) on the named map."""
    return env.codec.action_at(map_name, x, y)


@pytest.fixture(autouse=True)
def _sb3_logs_in_pytest_tmp(tmp_path_factory: pytest.TempPathFactory, monkeypatch: pytest.MonkeyPatch) -> None:
    """SB3 makes a log folder for every ``learn()`` without a logger, in the system's temp folder (about 135 per run of
    the suite): keep the suite's in pytest's own temp folder, which pytest cleans."""
    monkeypatch.setenv("SB3_LOGDIR", str(tmp_path_factory.getbasetemp() / "sb3_logs"))
