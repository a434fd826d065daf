"""Gymnasium's RecordVideo on ShelfSort-v0: one mp4 per recorded episode, one frame per state."""

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.wrappers import RecordVideo

pytest.importorskip("moviepy", reason="RecordVideo needs moviepy (the project's [extra] dependencies)")


def test_record_video_writes_every_state_of_an_episode(tmp_path):
    env = RecordVideo(gym.make("ShelfSort-v0", num_objects=2, render_mode="rgb_array", max_actions=3), str(tmp_path),
                      episode_trigger=lambda episode: True, disable_logger=True)
    env.reset(seed=0)
    steps, done = 0, False
    while not done:
        _, _, terminated, truncated, _ = env.step(int(np.flatnonzero(env.unwrapped.action_masks())[0]))
        steps, done = steps + 1, terminated or truncated
    env.close()
    videos = sorted(tmp_path.glob("*.mp4"))
    assert [v.name for v in videos] == ["rl-video-episode-0.mp4"]
    import imageio.v3 as iio

    frames = list(iio.imiter(videos[0]))
    assert len(frames) == steps + 1 and frames[0].shape == (480, 640, 3)
