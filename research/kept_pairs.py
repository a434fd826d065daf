"""Do checkpoints rank the kept corrections of a training run? (issue 10 diagnostic)

A run with the lookahead teacher's counterfactuals (``demo_counterfactuals``) or under its supervisor
(``guard``, `shelf_env.privileged.lookahead.FallGuard`) keeps, in its replay buffer's demonstration store, pairs
of transitions of one state: an action that would have dropped an object (non-expert, terminal,
-10) followed by the teacher's (expert). For each checkpoint this prints how it values the two at
those training states: the mean Q of each and the share of pairs where the teacher's action is
valued above the vetoed one, for the teacher's counterfactuals (collected with the demonstrations)
and for the supervisor's corrections (the learner's own vetoed actions, the last ``n_corrections``
pairs). Set against `research/fall_prediction.py`'s held-out ranking, it tells fitting from
generalising.

    python research/kept_pairs.py runs/p_s_guard/replay.pkl results/training/p_s_guard.zip \\
        results/training/p_s_long.zip results/training/p_s_la.zip --out results/p_s_guard/kept_pairs.md

(``runs/p_s_guard/replay.pkl`` is written by ``bash results/p_s_guard/train.sh``; it is not committed.)
"""

from __future__ import annotations

import argparse
import pathlib
from typing import Any

import numpy as np

from sb3_pixeldqn import PixelDoubleDQN
from shelf_env.files import write_text_atomically


def kept_pairs(buffer_path: pathlib.Path, run_checkpoint: pathlib.Path) -> tuple[Any, np.ndarray, int]:
    """The run's demonstration store, the indices of its (vetoed, teacher's) pairs and its number of
    corrections (from the run's checkpoint)."""
    run = PixelDoubleDQN.load(run_checkpoint)
    run.load_replay_buffer(buffer_path)
    store = getattr(run.replay_buffer, "demonstrations", None)
    if store is None:
        raise ValueError(f"{buffer_path} has no demonstration store")
    n = store.n_stored
    expert, obs = store.expert[:n], store.observations[:n, 0]
    pairs = np.array([i for i in range(n - 1) if not expert[i] and expert[i + 1]
                      and np.array_equal(obs[i], obs[i + 1])], dtype=np.int64)
    return store, pairs, int(run.n_corrections)


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("buffer", type=pathlib.Path, help="the run's replay.pkl")
    p.add_argument("checkpoints", nargs="+", type=pathlib.Path, help="the run's own checkpoint first")
    p.add_argument("--out", type=pathlib.Path, default=None)
    args = p.parse_args(argv)
    store, pairs, n_corrections = kept_pairs(args.buffer, args.checkpoints[0])
    if n_corrections > len(pairs):
        raise ValueError(f"{args.checkpoints[0]} counts {n_corrections} corrections but the store holds only "
                         f"{len(pairs)} pairs: not this buffer's run")
    split = len(pairs) - n_corrections
    groups = {"teacher's counterfactuals": pairs[:split], "supervisor's corrections": pairs[split:]}
    actions = store.actions[:, 0, 0]
    lines = [f"Kept (vetoed, teacher's) pairs of `{args.buffer}` (training states):", "",
             "| pairs | n | checkpoint | mean Q(vetoed) | mean Q(teacher's) | teacher's valued above vetoed |",
             "|---|---|---|---|---|---|"]
    for path in args.checkpoints:
        model = PixelDoubleDQN.load(path)
        for group, sel in groups.items():
            if len(sel) == 0:
                continue
            q = np.concatenate([model.policy.q_map_values(store.observations[chunk, 0]).reshape(len(chunk), -1)
                                for chunk in np.array_split(sel, max(1, len(sel) // 64))])
            vetoed, taught = q[np.arange(len(sel)), actions[sel]], q[np.arange(len(sel)), actions[sel + 1]]
            lines.append(f"| {group} | {len(sel)} | {path.stem} | {vetoed.mean():.2f} | {taught.mean():.2f} "
                         f"| {np.mean(taught > vetoed) * 100:.0f} % |")
    text = "\n".join(lines) + "\n"
    print(text, end="")
    if args.out is not None:
        write_text_atomically(args.out, text)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
