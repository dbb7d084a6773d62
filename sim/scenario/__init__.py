"""INPUT: scenario files, motions, earthquake records, and the 6-DOF reference they make."""

from sim.scenario.files import Scenario, build_motions, build_reference, limit_warnings, list_scenarios, load_scenario
from sim.scenario.reference import Reference, reference_from_motions

__all__ = [
    "Reference",
    "Scenario",
    "build_motions",
    "build_reference",
    "limit_warnings",
    "list_scenarios",
    "load_scenario",
    "reference_from_motions",
]
