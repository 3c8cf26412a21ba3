"""Every built-in scenario meets its own expectations (through the pytest plugin's fixture)."""

import pytest

from tests.conftest import SCENARIOS

BUILT_IN = sorted(p for p in SCENARIOS.glob("*.yaml") if not p.name.startswith("_"))


@pytest.mark.parametrize("path", BUILT_IN, ids=[p.stem for p in BUILT_IN])
def test_built_in_scenario_passes(run_scenario, path):
    result = run_scenario(path, write=False)
    assert result.passed, result.failures or result.summary["safety"]["events"]


@pytest.mark.parametrize("durations, limit_deg", [([1.5] * 4, 0.5), ([3.0] * 4, 0.2)])
def test_hit_tracking_scales_with_speed(run_scenario, durations, limit_deg):
    fast = run_scenario(SCENARIOS / "hit_roundtrip.yaml", planner__segment_durations=durations,
                        duration=sum(durations) + 0.5, write=False)
    assert fast.passed and fast.metrics["tracking_rms_deg"] < limit_deg
