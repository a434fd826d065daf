"""sb3_pixeldqn: pixel-wise double deep Q-learning for Stable-Baselines3 (env-agnostic).

``PixelDoubleDQN("FCNPolicy", env).learn(...)`` trains fully convolutional Q-maps on any env with a
``Box(0, 255, (C, H, W), uint8)`` observation and a ``Discrete(n_maps * H * W)`` action space.
"""

from sb3_pixeldqn.actor import ActorVecEnv
from sb3_pixeldqn.buffers import HindsightRelabelReplayBuffer
from sb3_pixeldqn.callbacks import CurriculumCallback, QMapImageCallback
from sb3_pixeldqn.ensemble import QEnsemble
from sb3_pixeldqn.loop_breaker import LoopBreaker
from sb3_pixeldqn.pixel_dqn import PixelDoubleDQN
from sb3_pixeldqn.policies import PICK_AND_PUSH_MAPS, PICK_ONLY_MAPS, FCNPolicy

__version__ = "0.1.0"

__all__ = [
    "PICK_AND_PUSH_MAPS",
    "PICK_ONLY_MAPS",
    "ActorVecEnv",
    "CurriculumCallback",
    "FCNPolicy",
    "HindsightRelabelReplayBuffer",
    "LoopBreaker",
    "PixelDoubleDQN",
    "QEnsemble",
    "QMapImageCallback",
]
