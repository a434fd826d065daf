"""rl-zoo3's enjoy on a ``pixel_double_dqn`` run (greedy, without action masks; see `shelf_env.training.zoo`):

    python examples/zoo_enjoy.py --algo pixel_double_dqn --env ShelfSort-v0 --gym-packages shelf_env -f logs/ -n 40
"""

from rl_zoo3.enjoy import enjoy

from shelf_env.training.zoo import register

if __name__ == "__main__":
    register()
    enjoy()
