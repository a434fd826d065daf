"""``shelf-evaluate`` with the experiments' policy wrappers registered (``<zip>+fall-filter``, ``<zip>+veto``,
``<zip>+symmetric``, ``<zip>+tiered-filter``, ``<zip>+push-guard``, ``<zip>+pick-first``, ``<zip>+edge-guard``,
``<zip>+tall-guard``; ``h-d-1cm``, ``h-a-1cm`` and ``+shipped-filter``, `research.wrapped_heuristics`;
``<zip>+geometry-filter`` and ``<zip>+pick-guard`` are the product's, `shelf_env.fall_filter` and
`shelf_env.pick_guard`).

    python -m research.evaluate --policies results/fall_filter/model/p_s.zip+fall-filter ... (shelf-evaluate's options)
"""

from __future__ import annotations

import research.distilled_veto  # noqa: F401  (registers +veto)
import research.edge_guard  # noqa: F401  (registers +edge-guard)
import research.fall_risk  # noqa: F401  (registers +fall-filter with shelf_env.policies)
import research.push_guard  # noqa: F401  (registers +push-guard and +pick-first)
import research.symmetric_q  # noqa: F401  (registers +symmetric)
import research.tall_guard  # noqa: F401  (registers +tall-guard)
import research.tiered_filter  # noqa: F401  (registers +tiered-filter)
import research.wrapped_heuristics  # noqa: F401  (registers h-d-1cm, h-a-1cm and +shipped-filter)
from shelf_env.cli.evaluate import main

if __name__ == "__main__":
    raise SystemExit(main())
