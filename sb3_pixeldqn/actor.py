"""`ActorVecEnv`: acting overlapped with learning, an actor process feeding `PixelDoubleDQN`.

Sequentially, each env step of the training loop waits for a gradient step and each gradient step
for an env step; on two CPU cores one of them idles half the time. With an `ActorVecEnv` as the
model's env, a second process holds the env and a CPU copy of the Q-network and plays the model's
ε-greedy (masked) policy on its own, while `PixelDoubleDQN.learn` consumes its transitions in order,
stores them and trains exactly as it would have after stepping the env itself
(`benchmarks/overlap.py` measured 1.48× the env steps per hour at N = 3 and 1.66× at N = 8 on two
cores, docs/experiments/learning-recipe.md lever 9).

- **Same replay ratio.** The actor runs at most ``max_lag`` transitions ahead of those the learner
  has consumed, and the learner trains ``gradient_steps`` per ``train_freq`` consumed steps, so the
  gradient steps per env step are the sequential loop's.
- **Staleness.** The learner sends the online network's weights every ``sync_every`` gradient
  steps, and ε whenever it moved by more than ``EPSILON_SYNC`` or the warm-up (``learning_starts``)
  ended. An action is therefore chosen by weights up to ``sync_every`` updates old, in a state up to
  ``max_lag`` steps ahead of the learner. Runs are not reproducible step for step: which weights an
  action saw depends on timing.
- **A VecEnv of one env.** Before the first collection and after `reset` (which stops the acting
  and drops the transitions not consumed yet) it is an ordinary VecEnv run by the actor process:
  ``reset``, ``step``, ``env_method``, ``get_attr``, ``set_attr``, ``has_attr``, ``env_is_wrapped``
  (demonstrations, for instance, are collected through ``step``). While it acts, ``step`` is
  refused, and ``env_method`` / ``set_attr`` run between two of the actor's steps, in order with its
  transitions: they take effect from the next transition on, as on a `DummyVecEnv`. Transitions
  produced before such a call may still wait to be consumed after it; `pending_episode_ends` counts
  the episode ends among them, so that a callback counting episodes under a setting (the
  curriculum) can leave them out.
- The env is built in the actor process by ``env_fn`` (cloudpickled, so a lambda works) and wrapped
  in SB3's ``Monitor`` unless it already is, as SB3 wraps a Gymnasium env given to an algorithm.
  Errors in the actor process (``env_fn``, a step, a method) are raised again in the learner.
"""

from __future__ import annotations

import functools
import multiprocessing as mp
import pickle
import queue
import threading
import traceback
from collections import deque
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from multiprocessing.connection import Connection
from typing import Any, NamedTuple

import gymnasium as gym
import numpy as np
import torch as th
from stable_baselines3.common.env_util import is_wrapped
from stable_baselines3.common.monitor import Monitor
from stable_baselines3.common.vec_env import VecEnv
from stable_baselines3.common.vec_env.base_vec_env import CloudpickleWrapper, VecEnvIndices, VecEnvStepReturn

from sb3_pixeldqn.exploration import draw_masked_action

#: The learner sends ε again when it moved by more than this since the last time.
EPSILON_SYNC = 0.02
#: Seconds the learner waits for any message before checking that the actor process is alive.
POLL_SECONDS = 1.0


class Transition(NamedTuple):
    """One env step of the actor, as the learner stores it (arrays of one env)."""

    obs: np.ndarray  # (1, *obs_shape): the observation the action was chosen in
    action: np.ndarray  # (1,) int64
    new_obs: np.ndarray  # (1, *obs_shape): the next observation, or the next episode's first one
    reward: np.ndarray  # (1,) float32
    done: np.ndarray  # (1,) bool
    info: dict[str, Any]  # with "TimeLimit.truncated" and, at an episode's end, "terminal_observation"
    next_mask: np.ndarray | None  # (1, n_actions) bool: mask of the state reached (None: masks unused)


@dataclass
class ActingRules:
    """How the actor chooses actions: the model's current ε and mask settings."""

    epsilon: float
    explore_all: bool  # still in the warm-up: every action exploratory
    masked: bool  # greedy argmax within the env's action_masks()
    masked_exploration: bool  # exploratory actions drawn from the env's action_masks()
    n_maps: int


class ActorVecEnv(VecEnv):
    """One env in an actor process that acts for `PixelDoubleDQN` (see the module docstring).

    :param env_fn: builds the Gymnasium env (called in the actor process).
    :param max_lag: transitions the actor may produce ahead of the learner (>= 1).
    :param sync_every: learner gradient steps between two weight copies to the actor (>= 1).
    :param threads: torch CPU threads of the actor process (>= 1).
    :param start_method: multiprocessing start method; "spawn" (default) is safe with torch's threads.
    """

    def __init__(self, env_fn: Callable[[], gym.Env], max_lag: int = 8, sync_every: int = 20, threads: int = 1,
                 start_method: str = "spawn") -> None:
        if not callable(env_fn):
            raise ValueError(f"env_fn must be a callable that builds the env, got {env_fn!r}")
        for name, value in (("max_lag", max_lag), ("sync_every", sync_every), ("threads", threads)):
            if not isinstance(value, int) or value < 1:
                raise ValueError(f"ActorVecEnv {name} must be an int >= 1, got {value!r}")
        self.max_lag = max_lag
        self.sync_every = sync_every
        ctx: Any = mp.get_context(start_method)
        # Commands go down a pipe that a thread of the actor process always drains, and everything
        # the actor sends comes back through a queue whose feeder thread never blocks the actor: a
        # large message each way (weights down, transitions up) can then never deadlock.
        child, self._remote = ctx.Pipe(duplex=False)
        self._messages = ctx.Queue()
        self._consumed = ctx.Value("q", 0)
        self._process = ctx.Process(target=_actor_main, args=(child, self._messages, CloudpickleWrapper(env_fn),
                                                              self._consumed, max_lag, threads),
                                    daemon=True, name="ActorVecEnv")
        self._process.start()
        child.close()
        self._pending: deque[Transition] = deque()
        self._running = False
        self._policy: Any = None  # the policy the actor holds a copy of
        self._synced_updates = 0  # the learner's gradient steps when weights were last sent
        self._synced_rules: ActingRules | None = None  # the acting rules last sent
        self.closed = False
        try:
            observation_space, action_space = self._request("spaces")
        except BaseException:
            self._kill()
            raise
        super().__init__(1, observation_space, action_space)

    # ------------------------------------------------------------ messages
    def _recv(self) -> tuple[str, Any]:
        if self.closed:
            raise RuntimeError("ActorVecEnv is closed")
        while True:
            try:
                kind, payload = self._messages.get(timeout=POLL_SECONDS)
                break
            except queue.Empty:
                if not self._process.is_alive() and self._messages.empty():  # its last words arrive first
                    self.closed = True
                    raise RuntimeError(f"the actor process died (exit code {self._process.exitcode})") from None
        if kind == "error":
            self._running = False  # the actor stops acting after an error
            error, trace = payload
            raise error from RuntimeError(f"in the actor process:\n{trace}")
        return kind, payload

    def _send(self, command: str, payload: Any) -> None:
        if self.closed:
            raise RuntimeError("ActorVecEnv is closed")
        try:
            self._remote.send((command, payload))
        except (BrokenPipeError, ConnectionResetError) as err:
            self.closed = True
            raise RuntimeError(f"the actor process died (exit code {self._process.exitcode})") from err

    def _request(self, command: str, payload: Any = None) -> Any:
        """Send a command and return its reply; transitions that arrive first are kept for `receive`."""
        self._send(command, payload)
        while True:
            kind, data = self._recv()
            if kind == "reply":
                return data
            self._pending.append(data)

    # ------------------------------------------------------------ acting
    @property
    def acting(self) -> bool:
        """Whether the actor process is playing the policy on its own (between `act` and `reset`)."""
        return self._running

    def update(self, policy: Any, n_updates: int, rules: ActingRules, seed: int | None) -> None:
        """Give the actor the model's current policy and acting rules when due: the network on the
        first call (or for another policy than last time), its weights every ``sync_every``
        gradient steps, ε when it moved by more than ``EPSILON_SYNC`` or the warm-up ended."""
        if self._policy is not policy:  # the first call, or another model took this env: its network
            self._request("configure", {
                "policy_class": type(policy), "policy_kwargs": policy._get_constructor_parameters(),
                "weights": _weights(policy), "rules": rules, "seed": seed,
            })
            self._policy = policy
        else:
            assert self._synced_rules is not None  # set with the configuration
            new_weights = n_updates - self._synced_updates >= self.sync_every
            if not (new_weights or abs(rules.epsilon - self._synced_rules.epsilon) > EPSILON_SYNC
                    or rules.explore_all != self._synced_rules.explore_all):
                return
            self._send("sync", {"weights": _weights(policy) if new_weights else None, "rules": rules})
            if not new_weights:
                self._synced_rules = rules
                return
        self._synced_updates, self._synced_rules = n_updates, rules

    def act(self) -> None:
        """Start acting (after `update` configured the policy); a no-op while acting."""
        if self._policy is None:
            raise RuntimeError("ActorVecEnv.act needs the policy first (update)")
        if not self._running:
            self._request("run")
            self._running = True

    def receive(self) -> Transition:
        """The actor's next transition, in order (waits for it)."""
        if not self._running and not self._pending:
            raise RuntimeError("ActorVecEnv is not acting: call act() first")
        if self._pending:
            transition = self._pending.popleft()
        else:
            kind, transition = self._recv()
            assert kind == "transition", kind
        with self._consumed.get_lock():
            self._consumed.value += 1
        return transition

    def stats(self) -> dict[str, int]:
        """The actor's counters: ``produced`` (since the last reset) and ``consumed`` (the learner's)."""
        produced = self._request("stats")
        return {"produced": int(produced), "consumed": int(self._consumed.value)}

    # ------------------------------------------------------------ VecEnv
    def reset(self) -> np.ndarray:
        """Stop acting, drop the transitions not consumed yet, reset the env (with the seed and
        options set by ``seed`` / ``set_options``) and return its first observation."""
        obs = self._request("reset", (self._seeds[0], self._options[0] or None))
        self._running = False
        self._pending.clear()
        with self._consumed.get_lock():
            self._consumed.value = 0
        self._reset_seeds()
        self._reset_options()
        return np.asarray(obs)[None]

    def step_async(self, actions: np.ndarray) -> None:
        if self._running:
            raise RuntimeError("ActorVecEnv is acting on its own (PixelDoubleDQN.learn started it); "
                               "call reset() before stepping it by hand")
        self._actions = np.asarray(actions).reshape(-1)

    def step_wait(self) -> VecEnvStepReturn:
        obs, reward, done, info = self._request("step", int(self._actions[0]))
        return np.asarray(obs)[None], np.array([reward], dtype=np.float32), np.array([done]), [info]

    def close(self) -> None:
        if self.closed:
            return
        try:
            self._remote.send(("close", None))
            self._process.join(timeout=10)
        except (BrokenPipeError, OSError):
            pass
        self._kill()

    def _kill(self) -> None:
        if self._process.is_alive():
            self._process.terminate()
            self._process.join(timeout=5)
        self._remote.close()
        self._messages.cancel_join_thread()
        self._messages.close()
        self.closed = True

    def _check_indices(self, indices: VecEnvIndices) -> list[int]:
        ids = self._get_indices(indices)
        if list(ids) != [0]:
            raise IndexError(f"ActorVecEnv holds one env (index 0), got indices {indices!r}")
        return list(ids)

    def get_attr(self, attr_name: str, indices: VecEnvIndices = None) -> list[Any]:
        self._check_indices(indices)
        return [self._request("get_attr", attr_name)]

    def has_attr(self, attr_name: str) -> bool:
        return bool(self._request("has_attr", attr_name))

    def set_attr(self, attr_name: str, value: Any, indices: VecEnvIndices = None) -> None:
        self._check_indices(indices)
        self._request("set_attr", (attr_name, value))

    def env_method(self, method_name: str, *method_args: Any, indices: VecEnvIndices = None,
                   **method_kwargs: Any) -> list[Any]:
        self._check_indices(indices)
        return [self._request("env_method", (method_name, method_args, method_kwargs))]

    def env_is_wrapped(self, wrapper_class: type[gym.Wrapper], indices: VecEnvIndices = None) -> list[bool]:
        self._check_indices(indices)
        return [bool(self._request("is_wrapped", wrapper_class))]

    def pending_episode_ends(self) -> int:
        """Episode ends among the transitions the actor produced but the learner has not consumed
        yet. Right after `env_method` or `set_attr` these are all transitions produced before the
        call (its reply came after them), so their episodes ran under the old setting."""
        return sum(bool(t.done[0]) for t in self._pending)


def _weights(policy: Any) -> dict[str, np.ndarray]:
    return {k: v.detach().cpu().numpy().copy() for k, v in policy.q_net.state_dict().items()}


class _Actor:
    """The actor process's state: its env, the policy copy, the acting rules and counters."""

    def __init__(self, env: gym.Env, commands: queue.Queue, messages: Any, consumed: Any, max_lag: int) -> None:
        self.env = env
        self.commands = commands
        self.messages = messages
        self.consumed = consumed
        self.max_lag = max_lag
        self.obs: np.ndarray | None = None
        self.mask: np.ndarray | None = None
        self.policy: Any = None
        self.rules: ActingRules | None = None
        self.rng = np.random.default_rng()
        self.running = False
        self.produced = 0
        self.draw_masked = draw_masked_action

    def handle(self, command: str, payload: Any) -> bool:
        """Run one command; False for ``close``."""
        env = self.env
        reply: Any = None
        if command == "close":
            return False
        if command == "spaces":
            reply = (env.observation_space, env.action_space)
        elif command == "configure":
            self.policy = payload["policy_class"](**payload["policy_kwargs"]).to("cpu")
            self.policy.set_training_mode(False)
            self.load(payload["weights"])
            self.rules = payload["rules"]
            self.rng = np.random.default_rng(payload["seed"])
        elif command == "sync":  # no reply: the learner does not wait for it
            if payload["weights"] is not None:
                self.load(payload["weights"])
            self.rules = payload["rules"]
            return True
        elif command == "run":
            if self.obs is None:
                raise RuntimeError("the actor's env was never reset")
            self.running = True
        elif command == "reset":
            seed, options = payload
            self.obs, _ = env.reset(seed=seed, options=options)
            self.mask, self.running, self.produced = None, False, 0
            reply = self.obs
        elif command == "step":
            reply = self.step(int(payload))[1:5]  # obs, reward, done, info
        elif command == "stats":
            reply = self.produced
        elif command == "get_attr":
            reply = env.get_wrapper_attr(payload)
        elif command == "has_attr":
            reply = env.has_wrapper_attr(payload)
        elif command == "set_attr":
            setattr(env, *payload)
            self.mask = None  # the attribute may change the state
        elif command == "env_method":
            name, args, kwargs = payload
            reply = env.get_wrapper_attr(name)(*args, **kwargs)
            self.mask = None  # the method may have changed the state
        elif command == "is_wrapped":
            reply = is_wrapped(env, payload)
        else:
            raise ValueError(f"unknown actor command {command!r}")
        self.messages.put(("reply", reply))
        return True

    def load(self, weights: dict[str, np.ndarray]) -> None:
        self.policy.q_net.load_state_dict({k: th.from_numpy(v) for k, v in weights.items()})

    def step(self, action: int) -> tuple[np.ndarray, np.ndarray, float, bool, dict[str, Any], np.ndarray | None]:
        """One env step as a DummyVecEnv takes it: (obs before, obs after or of the next episode,
        reward, done, info, mask of the state reached when the rules use masks)."""
        env, before = self.env, self.obs
        obs, reward, terminated, truncated, info = env.step(action)
        done = bool(terminated or truncated)
        info = dict(info)
        info["TimeLimit.truncated"] = bool(truncated and not terminated)
        rules = self.rules
        uses_masks = rules is not None and (rules.masked or rules.masked_exploration)
        next_mask = np.asarray(env.get_wrapper_attr("action_masks")(), dtype=bool) if uses_masks else None
        self.mask = next_mask
        if done:
            info["terminal_observation"] = obs
            obs, _ = env.reset()
            self.mask = None
        self.obs = obs
        assert before is not None
        return before, obs, float(reward), done, info, next_mask

    def choose(self) -> int:
        """The model's ε-greedy action in the current state, within the masks the rules use."""
        rules = self.rules
        assert rules is not None and self.obs is not None
        if (rules.masked or rules.masked_exploration) and self.mask is None:
            self.mask = np.asarray(self.env.get_wrapper_attr("action_masks")(), dtype=bool)
        if rules.explore_all or self.rng.random() < rules.epsilon:
            if rules.masked_exploration:
                return self.draw_masked(self.mask, rules.n_maps, self.rng)  # type: ignore[arg-type]
            return int(self.rng.integers(int(self.env.action_space.n)))  # type: ignore[attr-defined]
        masks = self.mask[None] if rules.masked else None  # type: ignore[index]
        return int(np.asarray(self.policy.predict(self.obs[None], deterministic=True, action_masks=masks)[0])[0])

    def act(self) -> None:
        action = self.choose()
        before, obs, reward, done, info, next_mask = self.step(action)
        self.produced += 1
        self.messages.put(("transition", Transition(
            before[None], np.array([action], dtype=np.int64), np.asarray(obs)[None],
            np.array([reward], dtype=np.float32), np.array([done]), info,
            None if next_mask is None else next_mask[None])))

    def loop(self) -> None:
        """Act while running and less than ``max_lag`` ahead; run each command as it comes."""
        while True:
            ready = self.running and self.produced - self.consumed.value < self.max_lag
            try:
                if ready:
                    command, payload = self.commands.get_nowait()
                else:
                    command, payload = self.commands.get(timeout=0.002 if self.running else None)
            except queue.Empty:
                if ready:
                    self.guarded(self.act)
                continue
            if command == _EOF or not self.guarded(functools.partial(self.handle, command, payload)):
                return

    def guarded(self, fn: Callable[[], Any]) -> Any:
        """Run ``fn``; an exception goes to the learner (and stops the acting) instead of ending the process."""
        try:
            result = fn()
            return True if result is None else result
        except Exception as err:  # noqa: BLE001  (raised again in the learner)
            self.running = False
            trace = traceback.format_exc()
            self.messages.put(("error", (_picklable(err), trace)))
            return True


def _picklable(err: Exception) -> Exception:
    """``err``, or a RuntimeError naming it when it does not pickle (the queue pickles in a thread,
    where a failure would be lost)."""
    try:
        pickle.loads(pickle.dumps(err))
        return err
    except Exception:  # noqa: BLE001
        return RuntimeError(f"{type(err).__name__}: {err}")


#: What the actor's command reader queues when the learner's end of the pipe is gone.
_EOF = "_eof"


def _read_commands(remote: Connection, commands: queue.Queue) -> None:
    """The actor's reader thread: move every command from the pipe to ``commands`` at once."""
    try:
        while True:
            commands.put(remote.recv())
    except (EOFError, OSError):
        commands.put((_EOF, None))


def _actor_main(remote: Connection, messages: Any, env_fn: CloudpickleWrapper, consumed: Any, max_lag: int,
                threads: int) -> None:
    """The actor process: build the env, then serve commands and act until ``close`` (or the learner is gone)."""
    th.set_num_threads(threads)
    try:
        env = env_fn.var()
        if not isinstance(env, gym.Env):
            raise ValueError(f"ActorVecEnv env_fn must build a gymnasium.Env, it built {type(env).__name__}")
        if not is_wrapped(env, Monitor):
            env = Monitor(env)
    except Exception as err:  # noqa: BLE001  (raised again in the learner)
        messages.put(("error", (_picklable(err), traceback.format_exc())))
        messages.close()
        messages.join_thread()  # the error must reach the learner before this process exits
        return
    messages.cancel_join_thread()  # from here on, exit even when the learner never reads what is left
    commands: queue.Queue = queue.Queue()
    threading.Thread(target=_read_commands, args=(remote, commands), daemon=True).start()
    try:
        _Actor(env, commands, messages, consumed, max_lag).loop()
    finally:
        env.close()


__all__: Sequence[str] = ["ActingRules", "ActorVecEnv", "Transition"]
