"""Train with rl-zoo3's own entry point, ``pixel_double_dqn`` registered first:

    python examples/zoo_train.py --algo pixel_double_dqn --env ShelfSort-v0 --gym-packages shelf_env \\
        -conf examples/hyperparams/pixel_double_dqn.yml [any rl-zoo3 train option]

Saves where rl-zoo3 saves (``logs/pixel_double_dqn/ShelfSort-v0_<id>/``). Needs the ``zoo`` extra
(``pip install ".[zoo]"``). See `shelf_env.training.zoo`.
"""

from rl_zoo3.train import train

from shelf_env.training.zoo import register

if __name__ == "__main__":
    register()
    train()
