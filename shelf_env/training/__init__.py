"""Training `PixelDoubleDQN` on `ShelfSort-v0`: every setting and the presets (`config`), rl-zoo3's
entry (`zoo`), the model cards (`model_card`) and shipping a model (`ship`)."""

from shelf_env.training.config import PRESETS, TrainConfig, demo_policy, make_curriculum, make_env, make_model

__all__ = ["PRESETS", "TrainConfig", "demo_policy", "make_curriculum", "make_env", "make_model"]
