"""sb3_pixeldqn: pixel-wise double DQN with fully convolutional Q-maps for Stable-Baselines3.

The algorithm package is being built (issue 3); this module only reserves the namespace.
"""

__version__ = "0.1.0"
