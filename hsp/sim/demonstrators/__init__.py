"""Scripted demonstrators, one plan per task kind (ravens' oracles, with human variation).

A plan is a generator of :mod:`steps <hsp.sim.demonstrators.steps>`; it reads the true
poses through its context when it needs them, so later way-points see earlier results.
"""

from hsp.sim.demonstrators.painting import painting_plan
from hsp.sim.demonstrators.stacking import stacking_plan
from hsp.sim.demonstrators.tire_removal import tire_removal_plan

PLANS = {"painting": painting_plan, "stacking": stacking_plan, "tire_removal": tire_removal_plan}

__all__ = ["PLANS"]
