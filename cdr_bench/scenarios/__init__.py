"""Scenario registry: typed config (:mod:`.schema`) and YAML loading (:mod:`.loader`)."""

from cdr_bench.scenarios.loader import list_scenarios, load_scenario, registry_root
from cdr_bench.scenarios.schema import (
    Aircraft,
    Airway,
    Encounter,
    LearningIntruder,
    PlacedAircraft,
    ScenarioConfig,
    ScenarioError,
    field_docs,
    from_mapping,
)

__all__ = [
    "Aircraft",
    "Airway",
    "Encounter",
    "LearningIntruder",
    "PlacedAircraft",
    "ScenarioConfig",
    "ScenarioError",
    "field_docs",
    "from_mapping",
    "list_scenarios",
    "load_scenario",
    "registry_root",
]
