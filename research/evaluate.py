"""``shelf-evaluate`` with the experiments' policy wrappers registered (``<zip>+fall-filter``).

    python -m research.evaluate --policies results/fall_filter/model/p_s.zip+fall-filter ... (shelf-evaluate's options)
"""

from __future__ import annotations

import research.fall_risk  # noqa: F401  (registers +fall-filter with shelf_env.policies)
from shelf_env.cli.evaluate import main

if __name__ == "__main__":
    raise SystemExit(main())
