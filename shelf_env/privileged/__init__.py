"""Privileged teachers that read the simulator through forked copies (a robot cannot): the lookahead
(`lookahead`: `probe_step`, `probe_outcome`, ``h-d-lookahead``) and the teacher dataset built with it (`dataset`);
and an unoccluded top-down view of the scene (`topdown`). Training and diagnostics only; never a baseline."""

from shelf_env.privileged.lookahead import (
    LookaheadAccessibility,
    LookaheadDistance,
    Outcome,
    probe_outcome,
    probe_step,
)

__all__ = ["LookaheadAccessibility", "LookaheadDistance", "Outcome", "probe_outcome", "probe_step"]
