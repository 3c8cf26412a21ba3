"""Range-of-motion assessment on the simulated patients: what `rehabkit assess` measures against the profile.

The spring-damper person (P01 in L-Exos, `scenarios/lexos_patient.yaml`) moves by its profile's ranges: the
assessment should recover them (the test asks for 2°). The musculoskeletal person (MyoArm, moderate profile,
`scenarios/lexos_myoarm.yaml`) does not read ranges from the profile: its ranges emerge from its muscles, weakness,
contracture and straps — the figure shows how they compare with the typed profile. Each MyoArm joint is assessed on
its own (a safety stop in one joint's session leaves the others measured), the transparent robot keeping 1 N·m·s/rad
of damping and the stretch capped at 6 N·m; a session the safety envelope stopped is reported as such (a passive
end a safety stop cut short is the angle reached then, hatched: a bound on the range, not its end).

    python benchmarks/rom_assessment.py [--out benchmarks/results/rom_assessment.png]
"""

from __future__ import annotations

import argparse
import tempfile
import time
from pathlib import Path

import yaml

from rehabkit.core.setup.errors import SetupError
from rehabkit.rehab.assess import assess

ROOT = Path(__file__).resolve().parents[1]
CASES = {  # name: (scenario, profile, assess keyword arguments, one joint per session)
    "spring-damper (P01)": ("lexos_patient.yaml", "p01.yaml", {}, False),
    "musculoskeletal (MOD01)": ("lexos_myoarm.yaml", "moderate_hemiparesis.yaml",
                                {"damping": 1.0, "stretch_settings": {"max_torque_nm": 6.0}}, True),
}


def measure(scenario: str, options: dict, per_joint: bool, joints: list[str], work: Path) -> dict:
    """joint → (active, passive, ended by) or the reason it could not be measured."""
    out = {}
    groups = [[j] for j in joints] if per_joint else [joints]
    for group in groups:
        try:
            r = assess(ROOT / "scenarios" / scenario, work / "_".join(group), joints=group, **options)
        except SetupError as exc:  # (the session could not even start)
            for j in group:
                out[j] = str(exc).split(" (/")[0]
            continue
        for which, run in r.runs.items():
            if run.summary["safety"]["events"]:
                print(f"  {'/'.join(group)}: the {which} session was stopped: "
                      f"{run.summary['safety']['events'][0]['message']}")
        for j in group:
            out[j] = (r.active[j], r.passive[j], r.stopped_by[j])
    return out


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--out", default=str(ROOT / "benchmarks" / "results" / "rom_assessment.png"))
    args = p.parse_args()
    results = {}
    with tempfile.TemporaryDirectory() as tmp:
        for name, (scenario, profile, options, per_joint) in CASES.items():
            truth = yaml.safe_load((ROOT / "scenarios" / "patients" / profile).read_text())["joints"]
            t0 = time.perf_counter()
            results[name] = (truth, measure(scenario, options, per_joint, list(truth), Path(tmp) / name))
            print(f"{name}: {time.perf_counter() - t0:.1f} s")
    print(f"{'person':<26}{'joint':<14}{'profile active':>16}{'measured':>16}{'profile passive':>18}{'measured':>16}"
          "  passive ends by")
    for name, (truth, got) in results.items():
        for j, rom in truth.items():
            a, pv = rom["active_deg"], rom["passive_deg"]
            m = got[j]
            if isinstance(m, str):
                print(f"{name:<26}{j:<14}{a[0]:7.1f}..{a[1]:6.1f}  not measured: {m}")
                continue
            ma, mp, why = m
            act = f"{ma[0]:8.1f}..{ma[1]:6.1f}" if ma is not None else f"{'stopped':>16}"
            pas = "..".join(f"{e:6.1f}" if e is not None else "     –" for e in mp)
            print(f"{name:<26}{j:<14}{a[0]:7.1f}..{a[1]:6.1f}{act}{pv[0]:9.1f}..{pv[1]:6.1f}{pas:>16}"
                  f"  {' / '.join(w or '–' for w in why)}")
    plot(results, Path(args.out))
    print(f"wrote {args.out}")


def plot(results: dict, path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, len(results), figsize=(11, 4), sharey=True)
    for ax, (name, (truth, got)) in zip(axes, results.items()):
        for i, (j, rom) in enumerate(truth.items()):
            for k, (kind, colour) in enumerate((("passive", "tab:blue"), ("active", "tab:orange"))):
                x = i + (k - 0.5) * 0.36
                lo, hi = rom[f"{kind}_deg"]
                ax.bar(x, hi - lo, bottom=lo, width=0.16, color=colour, alpha=0.35,
                       label=f"profile {kind}" if i == 0 else None)
                m = got[j]
                span = None if isinstance(m, str) else (m[0] if kind == "active" else m[1])
                if span is not None and None not in span:
                    bound = kind == "passive" and any(w and w.startswith("safety") for w in m[2])
                    ax.bar(x + 0.17, span[1] - span[0], bottom=span[0], width=0.16, color=colour,
                           hatch="//" if bound else None, label=f"measured {kind}" if i == 0 else None)
                else:
                    ax.text(x + 0.17, lo, "stopped", ha="center", va="top", fontsize=6, rotation=90)
        ax.set_xticks(range(len(truth)), list(truth), rotation=20, fontsize=8)
        ax.set_title(name, fontsize=10)
        ax.grid(axis="y", alpha=0.3)
    axes[0].set_ylabel("range [deg]")
    axes[0].legend(fontsize=7, loc="lower left")
    fig.tight_layout()
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=100)


if __name__ == "__main__":
    main()
