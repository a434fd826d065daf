"""rl-zoo3's record_video on a ``pixel_double_dqn`` run (an mp4 under the run's ``videos/``):

    python examples/zoo_record.py --algo pixel_double_dqn --env ShelfSort-v0 -f logs/ -n 20

rl-zoo3's record_video has no ``--gym-packages`` (importing `shelf_env` here registers the env)
and ignores the run's ``env_kwargs``; they are read from the run's ``config.yml`` and passed as
``--env-kwargs`` unless given.
"""

import runpy
import sys

from shelf_env.training.zoo import register, saved_env_kwargs

if __name__ == "__main__":
    register()
    if "--env-kwargs" not in sys.argv:
        kwargs = saved_env_kwargs(sys.argv[1:])
        if kwargs:
            sys.argv += ["--env-kwargs", *(f"{key}:{value!r}" for key, value in kwargs.items())]
    runpy.run_module("rl_zoo3.record_video", run_name="__main__")  # rl-zoo3's script has no main()
