"""The evaluation protocol of §V (`protocol`: SR, AE, mAE per N over runs and seeds, cells, Fig. 10),
the report against the heuristics (`report`) and fall traces of evaluated episodes (`traces`)."""

from shelf_env.evaluation.protocol import (
    FAILURES,
    HELDOUT_SEED,
    EpisodeRecord,
    evaluate_cell,
    load_cells,
    run_episode,
    scene_seed,
    summarize,
)

__all__ = ["FAILURES", "HELDOUT_SEED", "EpisodeRecord", "evaluate_cell", "load_cells", "run_episode", "scene_seed",
           "summarize"]
