"""The simulated world (§IV-D.3): the cabinet, its target regions and physics (`cabinet`), the object
catalogues (`objects`) and the task's rules, sorted / invalid (`task`)."""

from shelf_env.world.cabinet import PHYSICS, Physics, Region, World, sample_regions
from shelf_env.world.objects import OBJECT_SETS, ObjectSpec, sample_specs
from shelf_env.world.task import Judgement, judge

__all__ = ["OBJECT_SETS", "PHYSICS", "Judgement", "ObjectSpec", "Physics", "Region", "World", "judge",
           "sample_regions", "sample_specs"]
