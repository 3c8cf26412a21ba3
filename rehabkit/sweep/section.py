"""The ``sweep:`` section, the sweep layer's in every scenario (an extension: validated, located and in the schema
like the core's sections, whether or not a sweep runs)."""

from __future__ import annotations

from typing import Any

from pydantic import Field

from rehabkit.core.plugins.hookspecs import hookimpl
from rehabkit.core.plugins.lifecycle import Section
from rehabkit.models.strict import StrictModel


class SweepSpec(StrictModel):
    """A study over this scenario (``rehabkit sweep``): every combination of ``grid`` values × ``seeds`` runs."""

    grid: dict[str, list[Any]] = Field({}, description="key path, as for --set → the values it takes")
    seeds: int = Field(1, ge=1, description="runs per grid point, with scenario seeds 0..seeds-1")
    timeout_s: float = Field(600.0, gt=0, description="a run taking longer is stopped and recorded as failed")
    metrics: list[str] = Field([], description="metrics the aggregate table shows (besides the expect: ones)")
    test_seeds: int | None = Field(None, ge=1, description="seeds the scenario's test runs (default: all)")
    keep_runs: bool = Field(False, description="each run's folder under runs/<run id>/: its summary.json and what "
                                               "the scenario writes (run.rrd unless logging.rrd is off, run.mcap "
                                               "with ros.bag)")


@hookimpl
def rehabkit_scenario_sections(registry) -> dict[str, Section]:
    return {"sweep": Section(SweepSpec, None, "a study over this scenario (rehabkit sweep)")}
